"""The calibrated robot with the hip rolls' effort limits set to the truth, alone and with the torso's mass and CoM
true, for ``floor_kick_gap.py --sim --calibrated OUT/<variant>``: ``cal_hiproll`` and ``cal_torso_hiproll``. A
diagnosis on validation motions (it reads the mismatch), never a selection. The residual network is copied unchanged.

    python benchmarks/results/floor_fair/kickc55/variants_hip.py CALIBRATED RUN OUT

RUN is a floor run folder: its ``results.json``'s mismatch is the truth.
"""

import json
import shutil
import sys
from pathlib import Path

import numpy as np

from wresdyn.data.dataset import load_dataset
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.paths import DEFAULT_DATASET
from wresdyn.robot.description import load_robot

HIPS = ("left_hip_roll", "right_hip_roll")

cal, run, out = (Path(a) for a in sys.argv[1:4])
floating = load_robot(load_dataset(DEFAULT_DATASET).robot_file, base="floating")
res = json.loads((run / "results.json").read_text())
truth = RealRobot(floating, Mismatch.from_dict(res["mismatch"], "the run's mismatch"), 500.0).physics()
names = list(floating.joint_names)
for name, torso in (("cal_hiproll", False), ("cal_torso_hiproll", True)):
    dst = out / name
    dst.mkdir(parents=True, exist_ok=True)
    for f in ("config.json", "residual.json", "policy.pt"):
        shutil.copy(cal / f, dst / f)
    d = json.loads((cal / "physics.json").read_text())
    if torso:
        b = d["body_names"].index("torso")
        d["body_inertia"][b] = (np.asarray(d["body_inertia"][b]) * truth.body_mass[b] / d["body_mass"][b]).tolist()
        d["body_mass"][b], d["body_com"][b] = float(truth.body_mass[b]), [float(x) for x in truth.body_com[b]]
    for j in HIPS:
        k = names.index(j)
        d["effort"][k] = float(truth.effort[k])
    (dst / "physics.json").write_text(json.dumps(d))
    print(f"{dst}: torso {'true' if torso else 'identified'}, hip roll limits true "
          + ", ".join(f"{j} {truth.effort[names.index(j)]:.1f}" for j in HIPS) + " N*m")
