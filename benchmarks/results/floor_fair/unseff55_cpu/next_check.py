"""NEXT.md's batch D checked on the CPU: each deploy command DRY=1 printed (NEXT_DRY) parses, with the new field set;
(f)'s ranges build on the committed calibrated folder, the hip rolls' effort ranges printed; each kept (e) of the
base runs (``full/floor_unvp_sN``) resumes under the batch's options, and C's committed (f) ``config.json`` is what
C's flags record today.

    python benchmarks/results/floor_fair/unseff55_cpu/next_check.py NEXT_DRY
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
cal = F / "full/unvp_fits/calibrated"
_, robot = load_data("data/uneven_probe/dataset.npz")
floating = load_robot(robot.source, gains=robot.gains, base="floating")
centre = run_physics(cal, floating)
names = list(floating.joint_names)
text = Path(sys.argv[1]).read_text()
for line in text.splitlines():
    if line.startswith("CUDA_VISIBLE_DEVICES"):
        _, _, args = parse_command(shlex.split(line)[4:])
        print("parsed:", args.out, {k: getattr(args.randomization, k) for k in
              ("unseen", "unseen_mass_add_kg", "unseen_com_offset", "unseen_effort_scale", "effort_from_data")})
dr = args.randomization
ranges, source = narrow_ranges(dr, floating, centre, cal)
print("ranges:", source.split("); ", 1)[-1])
for j in ("left_hip_roll", "right_hip_roll"):
    k = names.index(j)
    lo, hi = ranges.scale["effort"][0][k], ranges.scale["effort"][1][k]
    print(f"{j}: effort {centre.effort[k]:.1f} N*m x {lo:.3f}-{hi:.3f} "
          f"({centre.effort[k] * lo:.1f}-{centre.effort[k] * hi:.1f})")
for base in sorted(set(re.findall(r"src/(floor_unvp\w*_s\d)", text))):
    kept = F / "full" / base / "skills" / "e_randomized"
    saved = json.loads((kept / "config.json").read_text())["randomization"]
    meta = _run_of(1, "e_randomized", SkillPPOConfig(), FloorDeployConfig(), {"calibrated": Path("/x")}, {},
                   Path("/tmp/x"), replace(dr, seed=int(base[-1])))[3]
    check_resume(kept, {"randomization": saved}, {"randomization": json.loads(json.dumps(meta["randomization"]))})
    print(f"{base} e_randomized: resumes under the batch's options")
c = replace(dr, unseen_effort_scale=None)
for s in (0, 1, 2):
    f = F / "full" / f"floor_unvpc_s{s}" / "skills" / "f_calibrated_narrow"
    saved = json.loads((f / "config.json").read_text())["randomization"]
    same = json.loads(json.dumps(replace(c, seed=saved["seed"]).record())) == saved
    print(f"floor_unvpc_s{s} f_calibrated_narrow: C's flags record its config.json's randomization: {same}")
