"""A run's identifiability report recomputed from its identified physics and the data it was identified on (the
report's own step: :func:`wresdyn.identify.identifiability.identifiability` under the run's saved ``SysIdConfig``),
for a run whose ``identifiability.json`` was not kept. Writes ``identifiability.json`` and ``.md`` into OUT.

    python benchmarks/results/floor_fair/ident55_cpu/recompute_identifiability.py DATA RUN/identify OUT
"""

import dataclasses
import json
import sys
import time
from pathlib import Path

import torch

from wresdyn.data.loading import load_data
from wresdyn.identify.identifiability import identifiability, write_identifiability
from wresdyn.identify.sysid import SysIdConfig
from wresdyn.robot.physical import PhysicalParams

torch.set_num_threads(1)
ds, robot = load_data(sys.argv[1])
run, out = Path(sys.argv[2]), Path(sys.argv[3])
saved = json.loads((run / "config.json").read_text())["sysid"]
names = {f.name for f in dataclasses.fields(SysIdConfig)}
cfg = SysIdConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in saved.items() if k in names})
params = PhysicalParams.load(run / "physics.json", robot)
t = time.time()
found = identifiability(robot, ds, params, cfg)
out.mkdir(parents=True, exist_ok=True)
print(write_identifiability(out, found), f"wall {time.time() - t:.0f} s", flush=True)
