"""The uneven probe data's calibrated identification alone (stage 1 of ``fit_corrections``' hybrid, ``SysIdConfig()``
on the CPU) with the links' masses, centres of mass and inertias left at the robot file's (``fit`` = the joint
fields only, no ``"bodies"``): whether anchoring the links changes the hip limits the floor's kicks lose on.

    python benchmarks/results/floor_fair/kick55/run_identify.py DATA OUT
"""

import dataclasses
import sys
import time
from pathlib import Path

import torch

from wresdyn.data.loading import load_data
from wresdyn.identify.sysid import SysIdConfig, identify
from wresdyn.identify.sysid_config import JOINT_FIELDS

torch.set_num_threads(1)
ds, robot = load_data(sys.argv[1])
cfg = dataclasses.replace(SysIdConfig(), device="cpu", fit=tuple(JOINT_FIELDS))
t = time.time()
identify(robot, ds, cfg, out=Path(sys.argv[2]), log=lambda s: print(s, flush=True))
print(f"wall {time.time() - t:.0f} s")
