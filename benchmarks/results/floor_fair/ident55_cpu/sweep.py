"""The effort line search's settings on validation: the search run on an identification's selected parameters (a run
without it, ``physics.json``: what ``identify`` hands the search, the shared ratio applied) at each number of points
and tolerance, as ``identify`` would run it after the same selection; prints validation [rad] per setting and, as a
diagnosis only, the searched limits against the true robot's.

    python benchmarks/results/floor_fair/ident55_cpu/sweep.py DATA RUN_WITHOUT
"""

import dataclasses
import sys
from pathlib import Path

import numpy as np
import torch

from wresdyn.data.loading import load_data
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.identify.sysid import PhysicsScore, SysIdConfig
from wresdyn.identify.unexcited_limits import search_unexcited_efforts
from wresdyn.sim.physics import PhysicalParams

POINTS = (4, 8, 16)
TOLERANCES = (0.0, 0.01, 0.02, 0.05, 0.1)

torch.set_num_threads(1)
ds, robot = load_data(sys.argv[1])
start = PhysicalParams.load(Path(sys.argv[2]) / "physics.json")
truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch, "the dataset's mismatch"), float(ds.rate_hz)).physics()
score = PhysicsScore(robot, ds.split("validation"), ds.rate_hz, weights=ds.fit_weights())
v0 = score(start)
print(f"without: validation {v0:.6f} rad")
print("| points | tolerance | validation [rad] | changed limits [N·m] (×truth, diagnosis) |\n|---|---|---|---|")
for points in POINTS:
    for tol in TOLERANCES:
        cfg = dataclasses.replace(SysIdConfig(), effort_line_points=points, effort_line_tolerance=tol)
        out, v = search_unexcited_efforts(cfg, robot, ds, ds.split("train"), 1.0 / ds.rate_hz, start, score, v0,
                                          lambda s: None)
        moved = np.flatnonzero(out.effort != start.effort)
        cells = ", ".join(f"{robot.joint_names[j]} {start.effort[j]:.1f} → {out.effort[j]:.1f} "
                          f"({out.effort[j] / truth.effort[j]:.2f}×)" for j in moved)
        print(f"| {points} | {tol:g} | {v:.6f} | {cells or 'none'} |", flush=True)
