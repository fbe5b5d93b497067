"""Where one gradient-fit iteration's time goes on a GPU: kernels per iteration by kind, their GPU time, and the
wall-clock of the iteration eager and replayed from its CUDA graph.

    python benchmarks/speed/profile_gradfit.py --device cuda:0 --windows 1024 --horizon 64 [--fused] [--top 30]

Workload: the shipped benchmark (``data/dataset.npz``, the project humanoid, 21 DoF), the default gradient-fit
configuration at ``--windows`` windows of ``--horizon`` steps, built as :func:`wresdyn.fit.gradfit.fit` builds it
(the same :class:`~wresdyn.fit.gradfit.GradFitIteration`). One eager iteration runs under ``torch.profiler`` (CUPTI sees
Warp's kernels as well as torch's); kernels are grouped as the solver's forward step, its adjoint, Warp copies and
memsets, and torch (the residual network, the loss, autograd, Adam). Then ``--repeat`` iterations are timed eagerly
and replayed from the graph. The graph's wall-clock against the kernels' summed GPU time shows how much of it is
the GPU's per-node overhead (launch-bound) rather than work. ``--fused`` profiles the opt-in fused MLP path
(``GradFitConfig.fused_network``), ``--tiles`` with it its Warp tile kernels (``network_tiles``); ``--top N`` also
lists the N kernels of most GPU time by name, with their count per step, to show which kernels a further fusion would
have to remove.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def kernel_kind(name: str) -> str:
    """A kernel's group: the replay solver's forward (step, rollout), its adjoint (their backward kernels and the
    adjoint's pieces), other Warp kernels, copies, memsets, torch."""
    n = name.lower()
    if "replay_" in n:
        return "solver adjoint" if ("backward" in n or "replay_piece" in n) else "solver forward"
    if "memset" in n:
        return "memset"
    if "memcpy" in n:
        return "copy"
    if "cuda_kernel" in n:  # other Warp kernels
        return "warp other"
    return "torch"


def main() -> None:
    import numpy as np
    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.fit.gradfit import GradFitConfig, GradFitIteration, build_policy
    from wresdyn.learn.adam import Adam
    from wresdyn.learn.residual import obs_stats
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim import Simulator, TrajectoryBank

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--windows", type=int, default=1024)
    p.add_argument("--horizon", type=int, default=64)
    p.add_argument("--repeat", type=int, default=20, help="iterations timed per mode")
    p.add_argument("--fused", action="store_true", help="GradFitConfig.fused_network: the fused MLP path and Adam")
    p.add_argument("--tiles", action="store_true", help="GradFitConfig.network_tiles (with --fused): Warp tile kernels")
    p.add_argument("--top", type=int, default=0, help="also list the N kernels of most GPU time by name")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    if not args.device.startswith("cuda"):
        raise SystemExit("profile_gradfit: needs a CUDA device (--device cuda:0)")
    wp.config.quiet = True
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    dataset = load_dataset(args.data, robot=robot)
    cfg = GradFitConfig(windows=args.windows, horizon=args.horizon, horizon_curriculum=(), device=args.device,
                        fused_network=args.fused, network_tiles=args.tiles)
    train = dataset.split("train")
    policy = build_policy(robot, cfg.residual, *obs_stats(train)).to(args.device)
    sim = Simulator(robot, cfg.windows, 1.0 / dataset.rate_hz, device=args.device, requires_grad=True)
    bank = TrajectoryBank(train, sim.device)
    rng, gen = np.random.default_rng(0), torch.Generator(device=args.device).manual_seed(0)
    h, b, n = args.horizon, args.windows, robot.n_dof

    def inputs():
        traj, start = bank.draw(rng, b, h)
        return traj, start, h, torch.randn((h, b, 4 * n), generator=gen, device=sim.device), cfg.lr

    def timed(step, count):
        torch.cuda.synchronize()
        t = time.perf_counter()
        for _ in range(count):
            step(*inputs())
        torch.cuda.synchronize()
        return (time.perf_counter() - t) / count

    rows = {}
    for graph in (False, True):
        optim = Adam(policy.parameters(), lr=cfg.lr, capturable=graph, fused=args.fused or None)
        step = GradFitIteration(cfg, sim, bank, policy, optim, cfg.obs_noise, graph)
        timed(step, 3)  # compile, warm up; with graphs: the eager warm-up, the capture, a replay
        if not graph:
            with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CUDA]) as prof:
                step(*inputs())
                torch.cuda.synchronize()
            count, busy = defaultdict(int), defaultdict(float)
            by_name = defaultdict(lambda: [0, 0.0])  # kernel name -> [count, GPU seconds]
            for e in prof.events():
                if e.device_type == torch.autograd.DeviceType.CUDA:
                    count[kernel_kind(e.name)] += 1
                    busy[kernel_kind(e.name)] += e.device_time * 1e-6  # us -> s
                    by_name[e.name][0] += 1
                    by_name[e.name][1] += e.device_time * 1e-6
            rows["kernels"] = {k: {"count": count[k], "gpu_ms": 1e3 * busy[k]} for k in sorted(count)}
            top = sorted(by_name.items(), key=lambda kv: -kv[1][1])[:args.top]
            rows["top"] = [{"name": k[:160], "kind": kernel_kind(k), "count": c, "gpu_ms": 1e3 * t}
                           for k, (c, t) in top]
        rows["graph" if graph else "eager"] = {"ms_per_iteration": 1e3 * timed(step, args.repeat)}
    kernels = rows["kernels"]
    total = sum(v["count"] for v in kernels.values())
    busy = sum(v["gpu_ms"] for v in kernels.values())
    name = torch.cuda.get_device_name(args.device)
    print(f"{name}; humanoid {n} DoF; {b} windows x {h} steps (forward and backward through each)")
    print("| kernels of one iteration | count | per step | GPU time [ms] |")
    print("|---|---|---|---|")
    for k, v in sorted(kernels.items(), key=lambda kv: -kv[1]["gpu_ms"]):
        print(f"| {k} | {v['count']} | {v['count'] / h:.1f} | {v['gpu_ms']:.2f} |")
    print(f"| all | {total} | {total / h:.1f} | {busy:.2f} |")
    if rows.get("top"):
        print(f"\nthe {len(rows['top'])} kernels of most GPU time (fused_network {args.fused}):")
        print("| kernel | kind | count | per step | GPU time [ms] |")
        print("|---|---|---|---|---|")
        for r in rows["top"]:
            print(f"| {r['name'][:90]} | {r['kind']} | {r['count']} | {r['count'] / h:.2f} | {r['gpu_ms']:.3f} |")
    g, e = rows["graph"]["ms_per_iteration"], rows["eager"]["ms_per_iteration"]
    print(f"\niteration wall-clock: eager {e:.1f} ms, CUDA graph {g:.1f} ms ({e / g:.1f}x); kernels busy {busy:.1f} ms "
          f"= {100 * busy / g:.0f} % of the graph's time; {1e3 * (g - busy) / total:.1f} us per kernel beyond its work")
    if args.json:
        Path(args.json).write_text(json.dumps({"device": name, "windows": b, "horizon": h, "fused_network": args.fused,
                                               "network_tiles": args.tiles, **rows,
                                               "kernels_total": total, "gpu_busy_ms": busy}, indent=1))


if __name__ == "__main__":
    main()
