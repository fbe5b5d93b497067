"""Where the gradient fit's fused paths part from the plain one, one piece at a time: the parameters' gradients of one
window batch, and Adam steps from the same gradients.

    python benchmarks/speed/gradfit_paths.py --device cuda:0 --windows 1024 --horizons 2,17,64 --json OUT.json

1. **Gradients.** The plain path, the fused path (``GradFitConfig.fused_network``) and with ``--tiles`` the tile path
   (``network_tiles``), each built as :func:`wresdyn.fit.gradfit.fit` builds it from the same seed (the same weights),
   take the same windows (drawn once per length) and observation noise through
   :meth:`~wresdyn.fit.gradfit.GradFitIteration.gradients` (rollout, loss, backward, the fused paths' finish), eagerly.
   Per path and window length: the loss against the plain path's, and per parameter the largest difference of its
   gradient over the plain gradient's largest magnitude.
2. **Adam.** From the plain path's weights and gradients (length ``--horizons``' last), ``--adam-steps`` steps of
   :class:`wresdyn.learn.adam.Adam` as the fused path runs it (torch's fused kernel) and as the plain path does
   (``capturable``, torch's foreach kernels), with the same gradients each step: the largest difference of the weights
   over the largest change the steps made.

Float32 rounding alone moves a gradient by about 1e-6 of its largest magnitude; a difference far above that is a
different computation, not another order of the same sums. The held-out split is never read.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def learner(robot, data, cfg):
    """The fit's learner for ``cfg`` as :func:`wresdyn.fit.gradfit.fit` builds it (seeded: the same initial weights
    for every path)."""
    from wresdyn.fit.gradfit import _FitLearner
    from wresdyn.learn.window_fit import start_window_fit

    rng, train, dt = start_window_fit(cfg, data)
    return _FitLearner(robot, data, cfg, None, rng, train, dt, lambda *_: None)


def gradients(fit, traj, start, h: int, noise):
    """(loss, the parameters' gradients) of one batch through ``fit``'s iteration (eager)."""
    fit.optim.zero_grad()
    loss, _ = fit._iteration.gradients(traj, start, h, noise)
    return float(loss.detach()), [p.grad.detach().clone() for p in fit.policy.parameters()]


def relative(a, b) -> float:
    """max |a − b| over max |b|."""
    return float((a - b).abs().max() / b.abs().max().clamp_min(1e-30))


def compare_gradients(robot, data, cfg, paths: dict, horizons, seed: int = 0) -> tuple[list[dict], object]:
    """Per window length: each path's loss and per-parameter relative difference from the plain path's gradient; and
    the plain path's learner (its gradients those of the last length)."""
    import numpy as np
    import torch

    fits = {name: learner(robot, data, dataclasses.replace(cfg, **flags)) for name, flags in paths.items()}
    plain = fits["plain"]
    rng = np.random.default_rng(seed)
    gen = torch.Generator(device=cfg.device).manual_seed(seed)
    out = []
    for h in horizons:
        traj, start = plain.bank.draw(rng, cfg.windows, h)
        noise = torch.randn((h, cfg.windows, plain.n_obs), generator=gen, device=cfg.device)
        ref_loss, ref = gradients(plain, traj, start, h, noise)
        row = {"horizon": h, "plain_loss": ref_loss, "paths": {}}
        for name, fit in fits.items():
            if name == "plain":
                continue
            loss, grads = gradients(fit, traj, start, h, noise)
            row["paths"][name] = {"loss_relative": abs(loss - ref_loss) / abs(ref_loss),
                                  "gradient_relative": {n: relative(g, r) for (n, _), g, r in
                                                        zip(fit.policy.named_parameters(), grads, ref)}}
        out.append(row)
    return out, plain


def compare_adam(plain, steps: int) -> dict:
    """``steps`` Adam steps with the plain path's current gradients, as the fit sets Adam up on a GPU
    (:func:`~wresdyn.learn.graph_step.adopt_optimiser`, ``capturable``; eager on the CPU): torch's fused kernel against
    its foreach ones."""
    import torch

    from wresdyn.learn.adam import Adam
    from wresdyn.learn.graph_step import adopt_optimiser

    params = [p.detach().clone() for p in plain.policy.parameters()]
    grads = [p.grad.detach().clone() for p in plain.policy.parameters()]
    runs = {}
    for name, fused in (("fused", True), ("foreach_capturable", False)):
        ps = [torch.nn.Parameter(p.clone()) for p in params]
        graph = params[0].is_cuda  # capturable where the fit captures (CUDA); the CPU runs Adam eagerly
        opt = Adam(ps, lr=plain.cfg.lr, capturable=graph, fused=fused or None)
        adopt_optimiser(opt, params[0].device, graph, fused)
        for _ in range(steps):
            for p, g in zip(ps, grads):
                p.grad = g.clone()
            opt.step()
        runs[name] = [p.detach() for p in ps]
    change = max(float((p - q).abs().max()) for p, q in zip(runs["foreach_capturable"], params))
    diff = max(float((p - q).abs().max()) for p, q in zip(runs["fused"], runs["foreach_capturable"]))
    return {"steps": steps, "largest_change": change, "largest_difference": diff, "relative": diff / change}


def main(argv=None) -> dict:
    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.fit.gradfit import GradFitConfig
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--windows", type=int, default=1024)
    p.add_argument("--horizons", default="2,17,64")
    p.add_argument("--tiles", action="store_true", help="also the tile path (network_tiles)")
    p.add_argument("--adam-steps", type=int, default=5)
    p.add_argument("--json", default="")
    args = p.parse_args(argv)
    wp.config.quiet = True
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset(args.data, robot=robot)
    cfg = GradFitConfig(windows=args.windows, device=args.device, iterations=10, cuda_graph=False)
    paths = {"plain": {"fused_network": False, "network_tiles": False},
             "fused": {"fused_network": True, "network_tiles": False}}
    if args.tiles:
        paths["tiles"] = {"fused_network": True, "network_tiles": True}
    horizons = [int(h) for h in args.horizons.split(",")]
    rows, plain = compare_gradients(robot, data, cfg, paths, horizons)
    result = {"device": args.device, "windows": args.windows, "gradients": rows,
              "adam": compare_adam(plain, args.adam_steps),
              "command": " ".join(["python", *sys.argv]), "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}
    for row in rows:
        for name, x in row["paths"].items():
            worst = max(x["gradient_relative"].items(), key=lambda kv: kv[1])
            print(f"H = {row['horizon']} {name}: loss {x['loss_relative']:.2e} relative; gradients "
                  + ", ".join(f"{n} {v:.1e}" for n, v in x["gradient_relative"].items()) + f" (largest {worst[0]})")
    a = result["adam"]
    print(f"Adam, {a['steps']} steps from the same gradients: fused against capturable foreach {a['relative']:.2e} of "
          f"the largest change ({a['largest_difference']:.2e} of {a['largest_change']:.2e})")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
