"""The next GPU session's commands checked on the CPU: each deploy command DRY=1 printed (NEXT_DRY) parses with
(f)'s option on; (f)'s ranges build on the calibrated folder with the recomputed report (CALIBRATED) and are refused on
the committed one (its report has no demand); each kept (e) of floor_unvp_s0-s2 resumes under the option.

    python benchmarks/results/floor_fair/limits55_cpu/next_check.py NEXT_DRY CALIBRATED
"""

import json
import shlex
import sys
from dataclasses import replace
from pathlib import Path

from wresdyn.cli import parse_command
from wresdyn.data.loading import load_data
from wresdyn.errors import WresdynError
from wresdyn.experiments.deploy_config import FloorDeployConfig
from wresdyn.experiments.skills import _run_of
from wresdyn.learn.runs import check_resume, run_physics
from wresdyn.robot import load_robot
from wresdyn.skills.randomize import narrow_ranges
from wresdyn.skills.skill_config import SkillPPOConfig

F = Path("benchmarks/results/floor_fair")
for line in Path(sys.argv[1]).read_text().splitlines():
    if line.startswith("CUDA_VISIBLE_DEVICES"):
        argv = shlex.split(line)[4:]
        _, _, args = parse_command(argv)
        print("parsed:", argv[-1], "effort_from_data =", args.randomization.effort_from_data)
dr = args.randomization
ds, robot = load_data("data/uneven_probe/dataset.npz")
floating = load_robot(robot.source, gains=robot.gains, base="floating")
for run in (Path(sys.argv[2]), F / "full/unvp_fits/calibrated"):
    try:
        _, source = narrow_ranges(dr, floating, run_physics(run, floating), run)
        print("ranges:", run, "->", source.split("; ")[-1])
    except WresdynError as e:
        print("refused:", e)
for s in (0, 1, 2):  # the kept (e) resumes under the option: its record never carries it
    kept = F / f"full/floor_unvp_s{s}/skills/e_randomized"
    saved = json.loads((kept / "config.json").read_text())["randomization"]
    meta = _run_of(1, "e_randomized", SkillPPOConfig(), FloorDeployConfig(), {"calibrated": Path("/x")}, {},
                   Path("/tmp/x"), replace(dr, seed=s))[3]
    check_resume(kept, {"randomization": saved}, {"randomization": json.loads(json.dumps(meta["randomization"]))})
    print(f"floor_unvp_s{s} e_randomized: resumes under the option")
