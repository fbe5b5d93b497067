"""(f)'s ranges of the uneven probe run's calibrated robot (`ident55_cpu/unvp55_fits/calibrated`, its recomputed
identifiability report) with `Randomization.unseen` off, on, and on with the IsaacLab-sourced mass and CoM ranges: the
torso, and the effort limit and dry friction of the hip rolls and an ankle roll. CPU, seconds.

    python benchmarks/results/floor_fair/kick55/unseen_ranges.py
"""

import torch

from wresdyn.data.loading import load_data
from wresdyn.learn.runs import run_physics
from wresdyn.robot import load_robot
from wresdyn.skills.randomize import Randomization, narrow_ranges

torch.set_num_threads(1)
ds, robot = load_data("data/uneven_probe/dataset.npz")
floating = load_robot(robot.source, gains=robot.gains, base="floating")
run = "benchmarks/results/floor_fair/ident55_cpu/unvp55_fits/calibrated"
centre = run_physics(run, floating)
torso, joints = list(floating.body_names).index("torso"), list(floating.joint_names)
for cfg in (Randomization(), Randomization(unseen="wide"),
            Randomization(unseen="wide", unseen_mass_add_kg=(-5.0, 5.0), unseen_com_offset=(0.05, 0.05, 0.01))):
    r, source = narrow_ranges(cfg, floating, centre, run)
    print(f"unseen={cfg.unseen} unseen_mass_add_kg={cfg.unseen_mass_add_kg} unseen_com_offset={cfg.unseen_com_offset}")
    print("  ", source)
    lo, hi = r.scale["body_mass"]
    print(f"   torso mass {centre.body_mass[torso]:.2f} kg x {lo[torso]:.3f}-{hi[torso]:.3f}, CoM ± {r.com_offset} m")
    for name in ("left_hip_roll", "right_hip_roll", "left_ankle_roll"):
        i = joints.index(name)
        print(f"   {name}: effort {centre.effort[i]:.1f} N·m x {r.scale['effort'][0][i]:.3f}-"
              f"{r.scale['effort'][1][i]:.3f}, friction {r.friction[0][i]:.3f}-{r.friction[1][i]:.3f} N·m")
