"""Diagnosis only, never a selection: each identification's effort limits against the true robot's (the dataset's
mismatch, :meth:`~wresdyn.data.real_robot.RealRobot.physics`), with the share of training samples on which each
drive's demanded torque exceeds the limit (``limit_unexcited_efforts``' measure) and each run's validation error
(the selection's score, recomputed from ``physics.json``).

    python benchmarks/results/floor_fair/ident55_cpu/limits.py DATA RUN [RUN ...]
"""

import sys
from pathlib import Path

import numpy as np
import torch

from wresdyn.data.loading import load_data
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.identify.sysid import PhysicsScore
from wresdyn.identify.unexcited_limits import demanded_torque
from wresdyn.sim.physics import PhysicalParams

torch.set_num_threads(1)
ds, robot = load_data(sys.argv[1])
runs = [Path(r) for r in sys.argv[2:]]
truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch, "the dataset's mismatch"), float(ds.rate_hz)).physics()
train, dt = ds.split("train"), 1.0 / ds.rate_hz
fits = [PhysicalParams.load(r / "physics.json") for r in runs]
score = PhysicsScore(robot, ds.split("validation"), ds.rate_hz, weights=ds.fit_weights())
print("validation [rad]: " + ", ".join(f"{r.name} {score(p):.6f}" for r, p in zip(runs, fits))
      + f", truth {score(truth):.6f}")


def share(p):
    return (demanded_torque(p, train, dt) > p.effort).mean(0)


head = "| joint | truth [N·m] | truth: saturated | " + " | ".join(f"{r.name}: limit (×truth), saturated" for r in runs)
print(head + " |\n|" + "---|" * (3 + len(runs)))
shares, true_share = [share(p) for p in fits], share(truth)
for j, name in enumerate(robot.joint_names):
    cells = [f"{p.effort[j]:.1f} ({p.effort[j] / truth.effort[j]:.2f}×), {100 * s[j]:.2f} %" for p, s in zip(fits, shares)]
    print(f"| {name} | {truth.effort[j]:.1f} | {100 * true_share[j]:.2f} % | " + " | ".join(cells) + " |")
