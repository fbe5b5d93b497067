"""The calibrated robot with the hip rolls' effort limits set to the truth, alone and with the torso's mass and CoM
true, for ``floor_kick_gap.py --sim --calibrated OUT/<variant>``: ``cal_hiproll`` and ``cal_torso_hiproll``. A
diagnosis on validation motions (it reads the mismatch), never a selection. The residual network is copied unchanged.

    python benchmarks/results/floor_fair/kickc55/variants_hip.py CALIBRATED RUN OUT

RUN is a floor run folder: its ``results.json``'s mismatch is the truth.
"""

import importlib.util
import sys
from pathlib import Path

HIPS = ("left_hip_roll", "right_hip_roll")

if __name__ == "__main__":
    here = Path(__file__).parent
    spec = importlib.util.spec_from_file_location("kick55_variants", here.parent / "kick55" / "variants.py")
    variants = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(variants)
    cal, run, out = (Path(a) for a in sys.argv[1:4])
    truth = variants.truth_of(run)
    for name, torso in (("cal_hiproll", False), ("cal_torso_hiproll", True)):
        variants.write_variant(cal, out / name, truth, torso, HIPS)
        print(f"{out / name}: torso {'true' if torso else 'identified'}, hip roll limits true "
              + ", ".join(f"{j} {truth.effort[truth.joint_names.index(j)]:.1f}" for j in HIPS) + " N*m")
