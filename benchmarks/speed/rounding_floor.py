"""How far float32 rounding alone moves the gradient fit's result: the fit run to iteration ``--at``, its network's
weights moved by one unit in the last place each (up or down at random, one generator per ``--nudges`` seed), then
resumed to the end; the final validation error of each against the same run resumed untouched (the control).

    python benchmarks/speed/rounding_floor.py --device cuda:0 --windows 1024 --iterations 2000 --nudges 1,2,3 --plain
    python benchmarks/speed/rounding_floor.py --device cpu --windows 32 --iterations 240 --nudges 1,2

A faster path whose sums run in another order (``--fused``, ``--tiles``: :class:`wresdyn.fit.gradfit.GradFitConfig`'s
``fused_network`` and ``network_tiles``) changes every iteration's gradients by about that much; how far the fit then
ends from the plain path (``--plain``; without a path option the fit's default, the tile path on CUDA) can be read
against how far a single such change moves the plain path itself. The nudge
goes through the fit's own checkpoint and resume (:func:`wresdyn.fit.gradfit.fit` with a run folder and ``until``),
so the control must end bit for bit where an uninterrupted fit does (the resume's promise; reported as
``control_final_validation``). Workload and schedule as ``gradfit_2000.py`` (the shipped humanoid and data, the fit's
defaults at ``--windows`` windows, a fixed ``--iterations``). The held-out split is never read.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def nudge(state: dict, names, seed: int) -> dict:
    """``state`` (a ``state_dict``) with each float entry named in ``names`` moved one unit in the last place, up or
    down at random (``torch.Generator`` seeded with ``seed``; the entries in ``names``' order)."""
    import torch

    gen = torch.Generator().manual_seed(seed)
    out = dict(state)
    for name in names:
        t = state[name]
        up = torch.rand(t.shape, generator=gen) < 0.5
        toward = torch.where(up.to(t.device), float("inf"), float("-inf")).to(t.dtype)
        out[name] = torch.nextafter(t, toward)
    return out


def resumed_fit(robot, dataset, cfg, at: int, seed: int | None, log=None) -> dict:
    """The fit of ``cfg`` to iteration ``at`` in a fresh run folder, the checkpoint's network weights nudged
    (:func:`nudge` with ``seed``; ``None``: untouched), then resumed to the end: its final and best validation [rad]
    and the returned weights' sum of absolute values."""
    import torch

    from wresdyn.fit.gradfit import fit
    from wresdyn.learn.runs import load_checkpoint, save_checkpoint

    quiet = log or (lambda *_: None)
    with tempfile.TemporaryDirectory(prefix="wresdyn_floor_") as d:
        policy, _ = fit(robot, dataset, cfg, out=d, log=quiet, until=at)
        if seed is not None:
            path = Path(d) / "checkpoint.pt"
            data = load_checkpoint(path)
            names = [n for n, _ in policy.named_parameters()]
            data["policy"] = nudge(data["policy"], names, seed)
            save_checkpoint(data, path)
        policy, curve = fit(robot, dataset, cfg, out=d, log=quiet)
    checks = [r["validation"] for r in curve if "validation" in r]
    params = torch.cat([p.detach().flatten().double().cpu() for p in policy.parameters()])
    return {"nudge_seed": seed, "final_validation": curve[-1].get("validation"),
            "best_validation": min(checks) if checks else None, "iterations": curve[-1]["iteration"],
            "returned_params_abs_sum": float(params.abs().sum())}


def floor(robot, dataset, cfg, nudges, at: int = 1, log=None) -> dict:
    """The control and one nudged run per seed of ``nudges`` (:func:`resumed_fit`), and each nudged run's distance
    from the control's final validation [rad]; ``floor_rad``: the largest of them."""
    if cfg.iterations is None or not 0 < at < cfg.iterations:
        raise ValueError("rounding_floor needs a fixed iterations and 0 < at < iterations")
    control = resumed_fit(robot, dataset, cfg, at, None, log)
    runs = [resumed_fit(robot, dataset, cfg, at, s, log) for s in nudges]
    for r in runs:
        r["distance_rad"] = abs(r["final_validation"] - control["final_validation"])
    return {"control": control, "nudged": runs, "at": at,
            "control_final_validation": control["final_validation"],
            "floor_rad": max((r["distance_rad"] for r in runs), default=None)}


def main(argv=None) -> dict:
    import torch

    from gradfit_2000 import workload, workload_arguments  # this folder: the same workload and options

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    workload_arguments(p)
    p.add_argument("--nudges", default="1,2,3", help="comma list of the nudges' generator seeds")
    p.add_argument("--at", type=int, default=1, help="the iteration after which the weights are nudged")
    p.add_argument("--json", default="", help="write the figures here")
    args = p.parse_args(argv)
    robot, dataset, cfg = workload(args)
    nudges = [int(s) for s in args.nudges.split(",") if s]
    result = floor(robot, dataset, cfg, nudges, args.at)
    name = torch.cuda.get_device_name(args.device) if args.device.startswith("cuda") else platform.processor() or "cpu"
    result.update({"machine": name, "device": args.device, "windows": args.windows, "iterations": args.iterations,
                   **dict(zip(("fused_network", "network_tiles"), cfg.network_paths())),
                   "command": " ".join(["python", *sys.argv]),
                   "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())})
    print(f"{name}, {args.device}; {args.iterations} iterations x {args.windows} windows; fused_network "
          f"{result['fused_network']}; network_tiles {result['network_tiles']}; weights nudged after iteration {args.at}")
    print(f"control (resumed untouched): final validation {result['control_final_validation']!r} rad")
    for r in result["nudged"]:
        print(f"nudge seed {r['nudge_seed']}: final validation {r['final_validation']!r} rad, "
              f"{r['distance_rad']:.3e} rad from the control")
    if result["floor_rad"] is not None:
        print(f"largest distance: {result['floor_rad']:.3e} rad")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
