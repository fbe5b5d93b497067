"""(f)'s effort-limit ranges on the reported configuration's corrections (``full/unvp_fits/calibrated``, its
identifiability report recomputed with the training data's demand: ``unvp_fits/calibrated/identify/`` here), with
``Randomization.effort_from_data`` off (today's ranges) and on. Diagnosis only, never a selection: where the true
limits of the uneven mismatch (the dataset's, ``data/mismatch_uneven.toml``) fall in each range. CPU, seconds.

    python benchmarks/results/floor_fair/limits55_cpu/effort_ranges.py
"""

import json
import shutil
import tempfile
from pathlib import Path

import torch

from wresdyn.data.loading import load_data
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.learn.runs import run_physics
from wresdyn.robot import load_robot
from wresdyn.skills.randomize import Randomization, narrow_ranges, unseen_parameters

torch.set_num_threads(1)
F = Path("benchmarks/results/floor_fair")
ds, robot = load_data("data/uneven_probe/dataset.npz")
floating = load_robot(robot.source, gains=robot.gains, base="floating")
truth = RealRobot(robot, Mismatch.load("data/mismatch_uneven.toml"), float(ds.rate_hz)).physics()
assert Mismatch.load("data/mismatch_uneven.toml").to_dict() == Mismatch.from_dict(ds.mismatch).to_dict()
report_path = F / "limits55_cpu/unvp_fits/calibrated/identify/identifiability.json"
report = json.loads(report_path.read_text())
run = Path(tempfile.mkdtemp()) / "calibrated"  # the calibrated run's physics with the recomputed report
(run / "identify").mkdir(parents=True)
shutil.copy(F / "full/unvp_fits/calibrated/physics.json", run)
shutil.copy(report_path, run / "identify")
centre = run_physics(run, floating)
joints = list(floating.joint_names)
unseen = unseen_parameters(report)
ranges = {}
for cfg in (Randomization(), Randomization(effort_from_data=True)):
    r, source = narrow_ranges(cfg, floating, centre, run)
    ranges[cfg.effort_from_data] = r
    print(f"effort_from_data={cfg.effort_from_data}: {source.replace(str(run), 'calibrated')}")


def where(x, lo, hi):
    return "below" if x < lo else "above" if x > hi else "inside"


print("\nlimits [N·m]; saturated: share of training samples on which the calibrated model's demand exceeds its limit;"
      " truth: diagnosis only\n")
print("| joint | identified | demanded | saturated | unseen in report | off: range (draw) | truth | off: truth"
      " | on: range (draw) | on: truth |")
print("|---|---|---|---|---|---|---|---|---|---|")
for j, name in enumerate(joints):
    if name not in report["demanded_effort_nm"]:
        continue
    c, t = float(centre.effort[j]), float(truth.effort[j])
    cells = []
    for on in (False, True):
        r = ranges[on]
        lo, hi = c * r.scale["effort"][0][j], c * r.scale["effort"][1][j]
        draw = "uniform" if r.effort_uniform is not None and r.effort_uniform[j] else "log-uniform"
        cells.append(f"{lo:.2f}-{hi:.2f} ({draw}) | " if not on else f"{lo:.2f}-{hi:.2f} ({draw}) | {where(t, lo, hi)}")
        if not on:
            cells[-1] += f"{t:.2f} | {where(t, lo, hi)} | "
    print(f"| {name} | {c:.2f} | {report['demanded_effort_nm'][name]:.2f} | "
          f"{100 * report['effort_saturated'][name]:.2f} % | {'yes' if f'effort:{name}' in unseen else 'no'} | "
          + "".join(cells) + " |")
