"""Per leg joint, the share of training samples on which its drive saturates: the identifiability report's measure
(:func:`wresdyn.identify.unexcited_limits.limit_unexcited_efforts`, ``saturated``: demanded |τ| above the limit) on
the default probe's and the ``across`` probe's recordings of the uneven mismatch, against three sets of limits.

python benchmarks/results/floor_fair/ankle_probe_cpu/shares.py DEFAULT.npz ACROSS.npz [FIT_PHYSICS.json] > shares.md
"""

import sys

import numpy as np

from wresdyn.data.loading import load_data
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.identify.unexcited_limits import limit_unexcited_efforts
from wresdyn.paths import REPO
from wresdyn.robot.physical import PhysicalParams

EARLIER = REPO / "benchmarks/results/floor_fair/full/unvp_fits/calibrated/identify/physics.json"


def shares(path, params):
    ds, robot = load_data(path)
    train = ds.split("train")
    _, found = limit_unexcited_efforts(params, robot.effort, train, 1.0 / ds.rate_hz)
    return robot, found.saturated


def main(default, across, fit=None):
    ds, robot = load_data(default)
    truth = RealRobot(robot, Mismatch.load(REPO / "data/mismatch_uneven.toml"), ds.rate_hz).physics()
    limits = {"truth (diagnosis)": truth, "default-probe fit": PhysicalParams.load(EARLIER, robot)}
    if fit:
        limits["across-probe fit"] = PhysicalParams.load(fit, robot)
    legs = [j for j, n in enumerate(robot.joint_names) if any(k in n for k in ("hip", "knee", "ankle"))]
    cols = [(f"{d} data, {k} limits", d, p) for k, p in limits.items() for d in ("default", "across")]
    got = {c: shares(default if d == "default" else across, p)[1] for c, d, p in cols}
    print("| joint | " + " | ".join(c for c, _, _ in cols) + " |")
    print("|---" * (len(cols) + 1) + "|")
    for j in legs:
        print(f"| {robot.joint_names[j]} | " + " | ".join(f"{100 * got[c][j]:.2f} %" for c, _, _ in cols) + " |")
    print()
    for k, p in limits.items():
        print(f"{k}: effort limits [N·m] " + ", ".join(f"{robot.joint_names[j]} {p.effort[j]:.1f}" for j in legs))


if __name__ == "__main__":
    main(*sys.argv[1:])
