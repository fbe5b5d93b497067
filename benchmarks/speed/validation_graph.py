"""One validation replay of the default fit, eager against captured as one CUDA graph (``wresdyn.sim.rollout_graph``).

    python benchmarks/speed/validation_graph.py [DATA] [--device cuda:0] [--repeats 10] [--json OUT.json]

What a model-selection call (:class:`wresdyn.learn.selection.ValidationScore`) runs: the validation split of DATA
(default ``data/dataset.npz``) replayed whole, open loop, on the shipped humanoid with the nominal physics (no
identified parameters), PD only and with the default residual MLP at its start (``ResidualConfig()``) on the same
device. Two simulators, one with ``rollout_graph`` off (the eager loop, the solver step still from its own graph) and
one with it on: the captured one's first call runs eagerly (warm-up), its second captures and replays (timed apart:
``capture_s``), the rest replay. The repeats alternate between the two (a shared host's load drifts alike for both);
the outputs are compared (max |Δq| over all samples, the diverged flags). On the CPU only the eager loop runs (a
smoke check: the CPU has no graphs).
"""

from __future__ import annotations

import argparse
import json
import platform
import statistics
import subprocess
import time

import numpy as np
import torch

from wresdyn.data.dataset import load_dataset
from wresdyn.fit.gradfit import build_policy
from wresdyn.learn.residual import ResidualConfig, obs_stats
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim import Simulator, replay_trajectories
from wresdyn.sim.rollout_graph import capture_blocker


def commit() -> str:
    try:
        out = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=True)
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], capture_output=True,
                               text=True).stdout.strip()
        return out.stdout.strip() + (" (uncommitted changes)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def timed(fn) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn()
    if torch.cuda.is_available():
        torch.cuda.synchronize()
    return time.perf_counter() - t0, out


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data", nargs="?", default="data/dataset.npz")
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--repeats", type=int, default=10)
    p.add_argument("--solver", default="auto")
    p.add_argument("--json", help="write the figures here")
    args = p.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    robot = load_robot(DEFAULT_ROBOT)
    ds = load_dataset(args.data, robot=robot)
    val = ds.split("validation")
    policy = build_policy(robot, ResidualConfig(), *obs_stats(ds.split("train"))).eval()
    sims = {"eager": Simulator(robot, len(val), 1.0 / ds.rate_hz, solver=args.solver, device=args.device)}
    sims["eager"].rollout_graph = False
    device = sims["eager"].device
    policy = policy.to(device)
    graphs = capture_blocker(device, grad=False, enabled=True, policy=policy, policy_device=device) is None
    if graphs:
        sims["captured"] = Simulator(robot, len(val), 1.0 / ds.rate_hz, solver=args.solver, device=args.device)
    steps = max(len(t.q) for t in val) - 1
    head = (f"{len(val)} validation trajectories, {steps} steps, solver {sims['eager'].solver_kind}, device {device}"
            f" ({torch.cuda.get_device_name(device) if device.type == 'cuda' else platform.processor() or 'cpu'}), "
            f"commit {commit()}")
    print(head)
    result = {"command": "python benchmarks/speed/validation_graph.py " + " ".join(
        [args.data, "--device", args.device, "--repeats", str(args.repeats), "--solver", args.solver]),
        "header": head, "trajectories": len(val), "steps": steps, "cases": {}}
    for case, pol in (("pd", None), ("residual", policy)):

        def run(name: str):
            return replay_trajectories(robot, val, ds.rate_hz, pol, sim=sims[name])

        rec: dict = {}
        first = {}
        for name in sims:  # the eager one's first call loads kernels; the captured one's is its eager warm-up
            rec[f"{name}_first_s"], first[name] = timed(lambda: run(name))
        if graphs:
            rec["capture_s"], _ = timed(lambda: run("captured"))  # captures, then replays once
        times = {name: [] for name in sims}
        outs = {}
        order = list(sims)
        for r in range(args.repeats):
            for name in order[r % len(order):] + order[:r % len(order)]:
                t, outs[name] = timed(lambda: run(name))
                times[name].append(t)
        for name, t in times.items():
            rec[f"{name}_s"] = t
            rec[f"{name}_median_s"] = statistics.median(t)
            rec[f"{name}_ms_per_step"] = 1e3 * min(t) / steps
            print(f"{case} {name}: first call {rec[f'{name}_first_s']:.3f} s; repeats "
                  + " ".join(f"{x:.3f}" for x in t) + f" s; median {statistics.median(t):.3f} s, min {min(t):.3f} s "
                  f"({rec[f'{name}_ms_per_step']:.3f} ms/step)")
        if graphs:
            a, b = outs["captured"], outs["eager"]
            diff = max(float(np.abs(x - y).max()) for g in b for x, y in zip(a[g].q, b[g].q))
            same_div = all(a[g].diverged_at == b[g].diverged_at for g in b)
            rec.update(max_abs_dq=diff, diverged_equal=same_div,
                       speedup=rec["eager_median_s"] / rec["captured_median_s"])
            print(f"{case} capture call (capture + one replay) {rec['capture_s']:.3f} s; eager/captured median "
                  f"{rec['speedup']:.2f}x; max |q_captured - q_eager| {diff:.3g} rad; diverged_at equal {same_div}")
        result["cases"][case] = rec
    if args.json:
        with open(args.json, "w") as f:
            json.dump(result, f, indent=1)


if __name__ == "__main__":
    main()
