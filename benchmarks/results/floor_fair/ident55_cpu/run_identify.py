"""The uneven probe data's calibrated identification alone (stage 1 of ``fit_corrections``' hybrid: ``SysIdConfig()``
on the CPU), with the effort line search at POINTS points (0: off) and an optional tolerance.

    python benchmarks/results/floor_fair/ident55_cpu/run_identify.py OUT POINTS [TOLERANCE]
"""

import dataclasses
import sys
import time
from pathlib import Path

import torch

from wresdyn.data.loading import load_data
from wresdyn.identify.sysid import SysIdConfig, identify

torch.set_num_threads(1)
ds, robot = load_data("data/uneven_probe/dataset.npz")
cfg = dataclasses.replace(SysIdConfig(), device="cpu", effort_line_points=int(sys.argv[2]),
                          **({"effort_line_tolerance": float(sys.argv[3])} if len(sys.argv) > 3 else {}))
t = time.time()
identify(robot, ds, cfg, out=Path(sys.argv[1]), log=lambda s: print(s, flush=True))
print(f"wall {time.time() - t:.0f} s")
