"""The shipped default data's identification (``SysIdConfig()``, the demo's) with the effort line search at POINTS
points (0: off), into OUT.

    python benchmarks/results/floor_fair/ident55_cpu/run_default.py OUT POINTS
"""

import dataclasses
import sys
import time
from pathlib import Path

import torch

from wresdyn.data.loading import load_data
from wresdyn.identify.sysid import SysIdConfig, identify

torch.set_num_threads(1)
ds, robot = load_data("data/dataset.npz")
cfg = dataclasses.replace(SysIdConfig(), effort_line_points=int(sys.argv[2]))
t = time.time()
identify(robot, ds, cfg, out=Path(sys.argv[1]), log=lambda s: print(s, flush=True))
print(f"wall {time.time() - t:.0f} s")
