"""One CPU validation replay timed in one process, the rollout before (a host read of the divergence at every step)
and after (the branch-free loop a CUDA graph captures) alternating repeat by repeat (the host is shared and its load
drifts: alternating gives each the same load). The validation trajectories of a dataset, whole, without gradients,
PD only and with the fit's default residual network at its start; the outputs of the two must be equal bit for bit.

    PYTHONPATH=TREE OMP_NUM_THREADS=1 python time_ab.py data/dataset.npz OLD_ROLLOUT_PY --rounds 9

``OLD_ROLLOUT_PY``: the earlier ``wresdyn/sim/rollout.py`` (``git show cc66594:wresdyn/sim/rollout.py``), loaded as a
module of the same package, so everything but the rollout is the tree's.
"""

from __future__ import annotations

import argparse
import importlib.util
import statistics
import sys
import time

import torch

from wresdyn.data.dataset import load_dataset
from wresdyn.fit.gradfit import build_policy
from wresdyn.learn.residual import ResidualConfig, obs_stats
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim import Simulator
from wresdyn.sim.bank import TrajectoryBank, servo_goal_accel

after = importlib.import_module("wresdyn.sim.rollout")  # the module: wresdyn.sim's `rollout` is the function


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data")
    p.add_argument("old")
    p.add_argument("--rounds", type=int, default=9)
    p.add_argument("--solver", default="replay")
    args = p.parse_args()
    torch.set_num_threads(1)
    torch.manual_seed(0)
    spec = importlib.util.spec_from_file_location("wresdyn.sim.rollout_before", args.old)
    before = sys.modules[spec.name] = importlib.util.module_from_spec(spec)  # dataclasses look their module up
    spec.loader.exec_module(before)
    robot = load_robot(DEFAULT_ROBOT)
    ds = load_dataset(args.data, robot=robot)
    val = ds.split("validation")
    sim = Simulator(robot, len(val), 1.0 / ds.rate_hz, solver=args.solver, device="cpu")
    window = TrajectoryBank(val, sim.device, 0.0, servo_goal_accel(robot, None, 1.0 / ds.rate_hz, sim.device)).whole()
    policy = build_policy(robot, ResidualConfig(), *obs_stats(ds.split("train"))).eval()
    print(f"{len(val)} trajectories, {window.steps} steps, solver {sim.solver_kind}, torch threads "
          f"{torch.get_num_threads()}")
    for case, pol in (("pd", None), ("residual", policy)):
        runs = {"before": before.rollout, "after": after.rollout}
        times = {name: [] for name in runs}
        with torch.no_grad():
            ref = before.rollout(sim, window, pol)  # warm-up, and the outputs the other must equal
            out = after.rollout(sim, window, pol)
            same = all(torch.equal(getattr(ref, f), getattr(out, f)) for f in ("q", "qd", "diverged_at")) and (
                (ref.actions is None and out.actions is None) or torch.equal(ref.actions, out.actions))
            order = list(runs)
            for r in range(args.rounds):
                for name in order[r % 2:] + order[:r % 2]:  # each goes first in turn
                    t0 = time.perf_counter()
                    runs[name](sim, window, pol)
                    times[name].append(time.perf_counter() - t0)
        for name, t in times.items():
            print(f"{case} {name}: " + " ".join(f"{x:.3f}" for x in t) + f" s; median {statistics.median(t):.3f} s, "
                  f"min {min(t):.3f} s ({1e3 * min(t) / window.steps:.3f} ms/step)")
        ratio = [a / b for a, b in zip(times["after"], times["before"])]
        print(f"{case} after/before per round: " + " ".join(f"{x:.3f}" for x in ratio)
              + f"; median {statistics.median(ratio):.3f}; outputs equal bit for bit: {same}")


if __name__ == "__main__":
    main()
