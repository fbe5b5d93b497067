"""The uneven probe data's calibrated robot (``fit_corrections``' calibrated branch, ``GradFitConfig()`` and
``SysIdConfig()`` on the CPU) with the effort line search at POINTS points, into OUT/calibrated.

    python benchmarks/results/floor_fair/ident55_cpu/fit_calibrated.py OUT POINTS
"""

import sys
import time
from dataclasses import replace
from pathlib import Path

import torch

from wresdyn.data.loading import load_data
from wresdyn.fit.gradfit import GradFitConfig, export_run
from wresdyn.fit.hybrid import fit_hybrid
from wresdyn.identify.sysid import SysIdConfig

torch.set_num_threads(1)
data = "data/uneven_probe/dataset.npz"
ds, robot = load_data(data)
out = Path(sys.argv[1]) / "calibrated"
t = time.time()
hybrid = fit_hybrid(robot, ds, replace(SysIdConfig(), device="cpu", effort_line_points=int(sys.argv[2])),
                    replace(GradFitConfig(), device="cpu"), out, data_path=data, log=lambda s: print(s, flush=True))
export_run(hybrid.policy, out, hybrid.config, ds, data, physics=hybrid.physics)
print(f"wall {time.time() - t:.0f} s")
