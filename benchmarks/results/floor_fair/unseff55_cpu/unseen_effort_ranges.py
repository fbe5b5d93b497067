"""(f)'s effort ranges on the uneven probe's calibrated fit (``full/unvp_fits/calibrated``, its committed report) with
candidate C's flags and with C plus ``--randomization.unseen-effort-scale 0.8 1.2`` (candidate D): every effort limit
the report marks unseen, the hip rolls first, in N·m. Reads the report only, never the mismatch.

    python benchmarks/results/floor_fair/unseff55_cpu/unseen_effort_ranges.py
"""

from pathlib import Path

from wresdyn.cli import parse_command
from wresdyn.data.loading import load_data
from wresdyn.learn.runs import run_physics
from wresdyn.robot import load_robot
from wresdyn.skills.randomize import narrow_ranges

CAL = Path("benchmarks/results/floor_fair/full/unvp_fits/calibrated")
C = ["--randomization.unseen", "wide", "--randomization.unseen-mass-add-kg", "-5", "5",
     "--randomization.unseen-com-offset", "0.05", "0.05", "0.01"]
D = [*C, "--randomization.unseen-effort-scale", "0.8", "1.2"]

_, robot = load_data("data/uneven_probe/dataset.npz")
floating = load_robot(robot.source, gains=robot.gains, base="floating")
centre = run_physics(CAL, floating)
names = list(floating.joint_names)
out = {}
for label, flags in (("C", C), ("D", D)):
    _, _, args = parse_command(["deploy", "--floor", *flags])
    ranges, source = narrow_ranges(args.randomization, floating, centre, CAL)
    out[label] = ranges.scale["effort"]
    print(f"## {label}: {' '.join(flags)}\n  {source.split('); ', 1)[-1]}")
b = names.index("left_hip_roll")
# the unseen effort limits: the joints whose range D changed (C gives them (e)'s x0.9-1.1)
changed = [j for j in range(len(names)) if (out["C"][0][j], out["C"][1][j]) != (out["D"][0][j], out["D"][1][j])]
order = sorted(changed, key=lambda j: ("hip_roll" not in names[j], names[j]))
print(f"\n{'joint':<22} {'identified':>10}   {'C factor':<13} {'C N*m':<13}   {'D factor':<13} {'D N*m':<13}")
for j in order:
    e = float(centre.effort[j])
    cells = []
    for label in ("C", "D"):
        lo, hi = float(out[label][0][j]), float(out[label][1][j])
        cells += [f"x{lo:.3f}-{hi:.3f}", f"{e * lo:.1f}-{e * hi:.1f}"]
    print(f"{names[j]:<22} {e:>10.1f}   {cells[0]:<13} {cells[1]:<13}   {cells[2]:<13} {cells[3]:<13}")
same = [names[j] for j in range(len(names)) if j not in changed]
print(f"\nunchanged by D ({len(same)} seen limits keep C's ranges): {', '.join(same)}")
