"""The calibrated robot with one group of its identified physics set to the truth, for the kick diagnosis's runs in
the calibrated simulator (``floor_kick_gap.py --sim --calibrated OUT/<variant>``): ``cal_torso`` (the torso's mass
and centre of mass true, its inertia scaled with the mass), ``cal_effort`` (every effort limit true) and
``cal_torso_effort`` (both). The residual network and its files are copied unchanged.

    python benchmarks/results/floor_fair/kick55/variants.py CALIBRATED RUN OUT

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



def truth_of(run: Path):
    """The true physics of a floor run's mismatch (its ``results.json``) on the floating humanoid."""
    floating = load_robot(load_dataset(DEFAULT_DATASET).robot_file, base="floating")
    res = json.loads((run / "results.json").read_text())
    return RealRobot(floating, Mismatch.from_dict(res["mismatch"], "the run's mismatch"), 500.0).physics()


def write_variant(cal: Path, dst: Path, truth, torso: bool, effort) -> None:
    """``cal``'s files in ``dst`` with the torso's mass and CoM true (its inertia scaled with the mass) when
    ``torso``, and the effort limits true for the joints ``effort`` names (``"all"``: every limit the truth sets)."""
    dst.mkdir(parents=True, exist_ok=True)
    for f in ("config.json", "residual.json", "policy.pt"):
        shutil.copy(cal / f, dst / f)
    d = json.loads((cal / "physics.json").read_text())
    if torso:
        b = d["body_names"].index("torso")
        d["body_inertia"][b] = (np.asarray(d["body_inertia"][b]) * truth.body_mass[b] / d["body_mass"][b]).tolist()
        d["body_mass"][b], d["body_com"][b] = float(truth.body_mass[b]), [float(x) for x in truth.body_com[b]]
    if effort == "all":
        e, t = np.asarray(d["effort"], float), np.asarray(truth.effort, float)
        d["effort"] = np.where(np.isfinite(t), t, e).tolist()
    else:
        for j in effort:
            k = truth.joint_names.index(j)
            d["effort"][k] = float(truth.effort[k])
    (dst / "physics.json").write_text(json.dumps(d))


if __name__ == "__main__":
    cal, run, out = (Path(a) for a in sys.argv[1:4])
    truth = truth_of(run)
    for name, torso, effort in (("cal_torso", True, False), ("cal_effort", False, True),
                                ("cal_torso_effort", True, True)):
        write_variant(cal, out / name, truth, torso, "all" if effort else ())
        print(f"{out / name}: torso {'true' if torso else 'identified'}, "
              f"effort limits {'true' if effort else 'identified'}")
