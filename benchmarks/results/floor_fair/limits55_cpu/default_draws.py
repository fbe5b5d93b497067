"""The option off draws what main drew, bit for bit: (e)'s and (f)'s randomised plants (6 worlds, seed 3, a first draw
and a redraw of two worlds; (f)'s ranges from the recomputed report here, around the robot file's values) saved to
OUT.npz. Run once under main's package and once under this branch's, then compare the arrays.

    git archive main wresdyn scenes | tar -x -C /tmp/main
    PYTHONPATH=/tmp/main python benchmarks/results/floor_fair/limits55_cpu/default_draws.py /tmp/d_main.npz
    PYTHONPATH=$PWD python benchmarks/results/floor_fair/limits55_cpu/default_draws.py /tmp/d_branch.npz
"""

import sys
from pathlib import Path

import numpy as np
import torch

from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim.physics import PhysicalParams
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.randomize import Randomization, narrow_ranges

torch.set_num_threads(1)
h = load_robot(DEFAULT_ROBOT)
run = Path(__file__).resolve().parent / "unvp_fits/calibrated"
out = {}
for name, narrow in (("e", False), ("f", True)):
    cfg = Randomization(seed=3)
    r = (cfg, narrow_ranges(cfg, h, PhysicalParams.nominal(h), run)[0]) if narrow else cfg
    p = SimPlant(h, 6, 500.0, 5, randomization=r)
    p.randomizer.draw(np.array([1, 4]))
    out |= {f"{name}_{k}": v.numpy() for k, v in p.randomizer.values.items()}
    out[f"{name}_delay"] = p.randomizer.delay
np.savez(sys.argv[1], **out)
