"""Probe: the MJCF round trip of an exported run with the replay solver's friction solve run to more Gauss-Seidel
sweeps (its default 8), to see how much of the two replays' difference is the solve's convergence.

    PYTHONPATH=. python benchmarks/results/export/mjcf_friction_sweeps_probe.py SWEEPS RUN OUT/robot.xml DATA
"""

import sys
import time
from pathlib import Path

import torch

from wresdyn.data.dataset import load_dataset
from wresdyn.data.loading import dataset_robot
from wresdyn.export.mjcf import ROUND_TRIP_TRAJECTORIES, round_trip
from wresdyn.learn.runs import run_physics
from wresdyn.sim.solver_replay.solver import SolverReplay

torch.set_num_threads(1)
sweeps, run, xml, data = int(sys.argv[1]), Path(sys.argv[2]), sys.argv[3], sys.argv[4]
_init = SolverReplay.__init__


def _more_sweeps(self, model, **kw):
    kw.setdefault("friction_sweeps", sweeps)
    _init(self, model, **kw)


SolverReplay.__init__ = _more_sweeps
ds = load_dataset(data)
robot = dataset_robot(ds.robot_file, None, ds.gains_config)
held = ds.split("heldout")[:ROUND_TRIP_TRAJECTORIES]
t0 = time.time()
r = round_trip(xml, robot, run_physics(run, robot), held, ds.rate_hz)
r.pop("q")
print("sweeps", sweeps, r, f"{time.time() - t0:.0f} s", flush=True)
