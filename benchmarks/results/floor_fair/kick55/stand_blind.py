"""What the stand's validation sees of the kick's causes: the identification's selection score (mean |Δq| over the
stand dataset's validation trajectories, replayed from ``physics.json``) for the calibrated robot as fitted and with
one group set to the truth (the dataset's mismatch) -- the torso's mass alone, its centre of mass alone, both (its
inertia scaled with the mass), the hips' roll limits, every limit -- and for the truth. Diagnosis of what stand
validation can choose.

    python benchmarks/results/floor_fair/kick55/stand_blind.py DATA CALIBRATED
"""

import dataclasses
import sys

import numpy as np
import torch

from wresdyn.data.loading import load_data
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.identify.sysid import PhysicsScore
from wresdyn.sim.physics import PhysicalParams

torch.set_num_threads(1)
ds, robot = load_data(sys.argv[1])
truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch, "the dataset's mismatch"), float(ds.rate_hz)).physics()
fit = PhysicalParams.load(f"{sys.argv[2]}/physics.json")
score = PhysicsScore(robot, ds.split("validation"), ds.rate_hz, weights=ds.fit_weights())
b = list(robot.body_names).index("torso")
hips = [list(robot.joint_names).index(j) for j in ("left_hip_roll", "right_hip_roll")]


def with_torso(p, what=("mass", "com", "inertia")):
    mass, com, inertia = (np.array(x, dtype=np.float64) for x in (p.body_mass, p.body_com, p.body_inertia))
    if "inertia" in what:
        inertia[b] *= truth.body_mass[b] / mass[b]
    if "mass" in what:
        mass[b] = truth.body_mass[b]
    if "com" in what:
        com[b] = truth.body_com[b]
    return dataclasses.replace(p, body_mass=mass, body_com=com, body_inertia=inertia)


def with_effort(p, joints):
    effort = np.array(p.effort, dtype=np.float64)
    effort[joints] = np.asarray(truth.effort)[joints]
    return dataclasses.replace(p, effort=effort)


every = [j for j in range(robot.n_dof) if np.isfinite(truth.effort[j])]
print(f"torso: fitted {fit.body_mass[b]:.2f} kg at {np.round(fit.body_com[b], 3)} m, "
      f"true {truth.body_mass[b]:.2f} kg at {np.round(truth.body_com[b], 3)} m")
for label, p in (("calibrated robot as fitted", fit), ("its torso mass true", with_torso(fit, ("mass",))),
                 ("its torso CoM true", with_torso(fit, ("com",))),
                 ("its torso mass and CoM true", with_torso(fit)),
                 ("its hip roll limits true", with_effort(fit, hips)), ("every limit true", with_effort(fit, every)),
                 ("torso and every limit true", with_effort(with_torso(fit), every)), ("the truth", truth)):
    print(f"{label:32s} stand validation {score(p):.6f} rad")
