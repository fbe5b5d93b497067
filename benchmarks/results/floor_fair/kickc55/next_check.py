"""NEXT.md's two batches checked on the CPU: each deploy command DRY=1 printed (NEXT_DRY, one ``## batch`` section
each) parses; (f)'s ranges build on the calibrated folder the session copies (CALIBRATED, the committed one with
``../limits55_cpu``'s report, the demand added, over it), with the torso's and the hip rolls' ranges printed; each
kept (e) of the batch's base runs resumes under the batch's options.

    python benchmarks/results/floor_fair/kickc55/next_check.py NEXT_DRY CALIBRATED
"""

import json
import re
import shlex
import sys
from dataclasses import replace
from pathlib import Path

from wresdyn.cli import parse_command
from wresdyn.data.loading import load_data
from wresdyn.experiments.deploy_config import FloorDeployConfig
from wresdyn.experiments.skills import _run_of
from wresdyn.learn.runs import check_resume, run_physics
from wresdyn.robot import load_robot
from wresdyn.skills.randomize import narrow_ranges
from wresdyn.skills.skill_config import SkillPPOConfig

F = Path("benchmarks/results/floor_fair")
cal = Path(sys.argv[2])
ds, robot = load_data("data/uneven_probe/dataset.npz")
floating = load_robot(robot.source, gains=robot.gains, base="floating")
centre = run_physics(cal, floating)
names, bodies = list(floating.joint_names), list(floating.body_names)
for section in Path(sys.argv[1]).read_text().split("## ")[1:]:
    if section.startswith("refused"):
        continue
    print("##", section.splitlines()[0].split(":")[0])
    for line in section.splitlines():
        if line.startswith("CUDA_VISIBLE_DEVICES"):
            _, _, args = parse_command(shlex.split(line)[4:])
            print("  parsed:", args.out, {k: getattr(args.randomization, k) for k in
                  ("unseen", "unseen_mass_add_kg", "unseen_com_offset", "effort_from_data")})
    dr = args.randomization
    ranges, source = narrow_ranges(dr, floating, centre, cal)
    print("  ranges:", source.split("); ", 1)[-1])
    b = bodies.index("torso")
    lo, hi = ranges.scale["body_mass"][0][b], ranges.scale["body_mass"][1][b]
    print(f"  torso {centre.body_mass[b]:.2f} kg x {lo:.3f}-{hi:.3f}, CoM ±{tuple(ranges.com_offset.tolist())} m")
    for j in ("left_hip_roll", "right_hip_roll", "right_ankle_pitch", "left_elbow"):
        k = names.index(j)
        lo, hi = ranges.scale["effort"][0][k], ranges.scale["effort"][1][k]
        print(f"  {j}: effort {centre.effort[k]:.1f} N*m x {lo:.3f}-{hi:.3f} "
              f"({centre.effort[k] * lo:.1f}-{centre.effort[k] * hi:.1f})")
    for base in sorted(set(re.findall(r"src/(floor_unvp\w*_s\d)", section))):
        kept = F / "full" / base / "skills" / "e_randomized"
        saved = json.loads((kept / "config.json").read_text())["randomization"]
        seed = int(base[-1])
        meta = _run_of(1, "e_randomized", SkillPPOConfig(), FloorDeployConfig(), {"calibrated": Path("/x")}, {},
                       Path("/tmp/x"), replace(dr, seed=seed))[3]
        check_resume(kept, {"randomization": saved}, {"randomization": json.loads(json.dumps(meta["randomization"]))})
        print(f"  {base} e_randomized: resumes under the batch's options")
