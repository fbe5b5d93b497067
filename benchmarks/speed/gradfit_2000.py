"""The gradient fit's whole fixed schedule, measured: training seconds, ms per iteration at each window length, and
the validation error at the end.

    python benchmarks/speed/gradfit_2000.py --device cuda:0 --iterations 2000 --windows 1024 --json OUT.json
    python benchmarks/speed/gradfit_2000.py --device cpu --iterations 12 --windows 4 --curriculum 2,4   # tiny
    python benchmarks/speed/gradfit_2000.py --device cuda:0 --iterations 2000 --windows 1024 --plain --json OUT.json
    python benchmarks/speed/gradfit_2000.py --device cuda:0 --iterations 2000 --windows 1024 --fused --json OUT.json

Workload: the shipped benchmark (``data/dataset.npz``, the project humanoid, 21 DoF, dt = 2 ms) and the gradient fit's
defaults (:class:`wresdyn.fit.gradfit.GradFitConfig`: MLP residual, horizon curriculum 2 ... 64 in equal parts,
cosine learning rate) at ``--windows`` windows. A fixed ``--iterations`` selects the fixed schedule
(:class:`~wresdyn.learn.schedule.FixedSchedule`), so the plateau rule never stops the run early: every one of the
iterations is run and timed. The fit itself is :func:`wresdyn.fit.gradfit.fit`, the code path of ``wresdyn fit``.

Reported: ``train_s``, the fit's own training wall-clock (validation checks excluded, the first iteration of each
window length's eager warm-up and its CUDA-graph capture included); per window length the iterations run and the ms
per iteration, measured between rows whose wall-clock is exact (rows where the loop waited for the device: its log
and validation rows on CUDA, every row on the CPU), skipping each length's first two iterations (warm-up and capture);
``overhead_s``, what ``train_s`` holds beyond those rates times the iterations (warm-ups, captures, waits); the loss
of the last iteration and the validation error after it (a faster path must give the same), the best validation and
its iteration (what ``fit`` returns). ``--no-graph`` runs CUDA eagerly (the peer). Without ``--plain``, ``--fused``
or ``--tiles`` the fit runs its default network path (:meth:`~wresdyn.fit.gradfit.GradFitConfig.network_paths`: the
tile path on CUDA, the plain one on the CPU); ``--plain`` turns ``GradFitConfig.fused_network`` and
``network_tiles`` off, ``--fused`` runs the fused path (the MLP's step in fewer kernels, fused Adam) and ``--tiles``
with it its tile kernels (the step's network forward and backward as one Warp tile kernel each). ``fused_network`` and
``network_tiles`` in the figures are the paths that ran. The held-out split is never read.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def exact_rows(curve: list[dict], cfg, deferred: bool) -> list[dict]:
    """The rows of ``curve`` whose ``wall`` is exact: every row of an eager fit; of a deferred one (CUDA graphs) the
    first two, and those at which the loop read the device back (its log and validation iterations)."""
    from wresdyn.learn.schedule import FixedSchedule

    if not deferred:
        return list(curve)
    sched = FixedSchedule(cfg, cfg.horizon_curriculum or (cfg.horizon,))
    last = cfg.iterations
    return [r for r in curve if r["iteration"] <= 2 or r["iteration"] == last
            or sched.log_now(r["iteration"] - 1) or sched.validate_now(r["iteration"] - 1)]


def per_length(curve: list[dict], cfg, deferred: bool) -> list[dict]:
    """Per window length (stage of the fixed schedule): its iterations, and ms per iteration between its first and
    last exact rows after the stage's first two iterations (``None`` where fewer than two such rows exist)."""
    from wresdyn.learn.schedule import FixedSchedule

    horizons = cfg.horizon_curriculum or (cfg.horizon,)
    sched = FixedSchedule(cfg, horizons)
    stage_of = {r["iteration"]: sched.at(r["iteration"] - 1)[0] for r in curve}
    exact = {r["iteration"] for r in exact_rows(curve, cfg, deferred)}
    out = []
    for s, h in enumerate(horizons):
        its = [r for r in curve if stage_of[r["iteration"]] == s]
        if not its:
            continue
        first = its[0]["iteration"]
        timed = [r for r in its if r["iteration"] in exact and r["iteration"] >= first + 2]
        # the rows' wall counts from the end of the previous row: the rate between two exact rows a and b covers
        # iterations a+1 ... b
        ms = None
        if len(timed) >= 2:
            a, b = timed[0], timed[-1]
            ms = 1e3 * (b["wall"] - a["wall"]) / (b["iteration"] - a["iteration"])
        out.append({"horizon": h, "iterations": len(its), "ms_per_iteration": ms,
                    "measured_over": [timed[0]["iteration"], timed[-1]["iteration"]] if ms is not None else None})
    return out


def measure(robot, dataset, cfg, log=print) -> dict:
    """Run the fit of ``cfg`` (a fixed ``iterations``) on ``dataset`` and return the figures (module docstring)."""
    import torch

    from wresdyn.fit.gradfit import fit

    if cfg.iterations is None:
        raise ValueError("gradfit_2000 measures a fixed schedule: give iterations")
    deferred = cfg.cuda_graph and cfg.device.startswith("cuda")
    t = time.perf_counter()
    policy, curve = fit(robot, dataset, cfg, log=log)
    if cfg.device.startswith("cuda"):
        torch.cuda.synchronize(cfg.device)
    process = time.perf_counter() - t
    lengths = per_length(curve, cfg, deferred)
    train = curve[-1]["wall"]
    rated = sum(x["iterations"] * x["ms_per_iteration"] / 1e3 for x in lengths if x["ms_per_iteration"] is not None)
    checks = [r for r in curve if "validation" in r]
    best = min(checks, key=lambda r: r["validation"]) if checks else None
    params = torch.cat([p.detach().flatten().double().cpu() for p in policy.parameters()])
    return {"iterations": len(curve), "windows": cfg.windows, "device": cfg.device, "cuda_graph": deferred,
            **dict(zip(("fused_network", "network_tiles"), cfg.network_paths())),
            "train_s": train, "process_s": process, "ms_per_iteration_mean": 1e3 * train / len(curve),
            "per_length": lengths,
            "overhead_s": train - rated if all(x["ms_per_iteration"] is not None for x in lengths) else None,
            "final_loss": curve[-1]["loss"], "final_validation": curve[-1].get("validation"),
            "best_validation": best["validation"] if best else None,
            "best_iteration": best["iteration"] if best else None,
            "returned_params_abs_sum": float(params.abs().sum()), "sim_steps": curve[-1]["sim_steps"]}


def _commit() -> str:
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def workload_arguments(p: argparse.ArgumentParser) -> None:
    """The workload's options (this script's and ``rounding_floor.py``'s): device, data, schedule, windows, seed and
    the fit's opt-in paths."""
    p.add_argument("--device", default="cpu")
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--iterations", type=int, default=2000, help="fixed schedule length (no plateau stop)")
    p.add_argument("--windows", type=int, default=1024)
    p.add_argument("--curriculum", default="", help="comma list of window lengths; default: the config's")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-graph", action="store_true", help="CUDA: run each iteration eagerly")
    p.add_argument("--plain", action="store_true", help="the plain path (fused_network and network_tiles off)")
    p.add_argument("--fused", action="store_true", help="GradFitConfig.fused_network: the fused MLP path and Adam")
    p.add_argument("--tiles", action="store_true", help="GradFitConfig.network_tiles (with --fused): Warp tile kernels")


def network_arguments(args) -> dict:
    """``GradFitConfig``'s ``fused_network`` and ``network_tiles`` of the options: ``--plain`` both off, ``--fused``
    the fused path (``--tiles`` its tile kernels), none of them the config's defaults (on CUDA the tile path)."""
    if args.plain and (args.fused or args.tiles):
        raise SystemExit("--plain runs neither the fused path nor its tiles")
    if args.plain or args.fused:
        return {"fused_network": args.fused, "network_tiles": args.tiles}
    return {"network_tiles": True} if args.tiles else {}


def workload(args):
    """``(robot, dataset, cfg)`` of :func:`workload_arguments`' options: the shipped humanoid and data, the fit's
    defaults at those settings (torch on one thread, Warp quiet)."""
    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.fit.gradfit import GradFitConfig
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    wp.config.quiet = True
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    dataset = load_dataset(args.data, robot=robot)
    cfg = GradFitConfig(windows=args.windows, device=args.device, iterations=args.iterations, seed=args.seed,
                        cuda_graph=not args.no_graph, **network_arguments(args))
    if args.curriculum:
        cfg = dataclasses.replace(cfg, horizon_curriculum=tuple(int(h) for h in args.curriculum.split(",")))
    return robot, dataset, cfg


def main(argv=None) -> dict:
    import torch

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    workload_arguments(p)
    p.add_argument("--json", default="", help="write the figures here")
    args = p.parse_args(argv)
    robot, dataset, cfg = workload(args)
    result = measure(robot, dataset, cfg, log=lambda m: print(m, flush=True))
    name = torch.cuda.get_device_name(args.device) if args.device.startswith("cuda") else platform.processor() or "cpu"
    result.update({"machine": name, "commit": _commit(), "command": " ".join(["python", *sys.argv]),
                   "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())})
    if args.tiles:  # the split the kernels ran (WRESDYN_TILE_BLOCK where set)
        from wresdyn.learn.tile_mlp import TileBlock

        result["tile_block"] = dataclasses.asdict(TileBlock.from_env())
    print(f"\n{name}, {args.device}; {result['iterations']} iterations x {args.windows} windows; "
          f"graph {result['cuda_graph']}; fused_network {result['fused_network']}; "
          f"network_tiles {result['network_tiles']}")
    print(f"training {result['train_s']:.2f} s ({result['ms_per_iteration_mean']:.2f} ms/iteration on average); "
          f"process {result['process_s']:.1f} s; overhead beyond the rates "
          + (f"{result['overhead_s']:.2f} s" if result["overhead_s"] is not None else "-"))
    print("| window length | iterations | ms/iteration | measured over rows |")
    print("|---|---|---|---|")
    for x in result["per_length"]:
        ms = f"{x['ms_per_iteration']:.2f}" if x["ms_per_iteration"] is not None else "-"
        over = "-" if x["measured_over"] is None else f"{x['measured_over'][0]}-{x['measured_over'][1]}"
        print(f"| {x['horizon']} | {x['iterations']} | {ms} | {over} |")
    val = result["final_validation"]
    print(f"final loss {result['final_loss']:.6e}; validation after the last iteration "
          + (f"{val:.5f} rad" if val is not None else "-")
          + (f"; best {result['best_validation']:.5f} rad at iteration {result['best_iteration']}"
             if result["best_validation"] is not None else ""))
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(result, indent=1))
    return result


if __name__ == "__main__":
    main()
