"""(f)'s successes per seed, validation and held-out, all motions and kicks, for the runs named on the command line
(folders under ../full/). Usage: python per_seed.py floor_unvpc floor_unvpw"""
import json
import sys
from pathlib import Path

FULL = Path(__file__).resolve().parent.parent / "full"
print("(f) f_calibrated_narrow on the real robot's floor, per seed: successes / motions, all and kick family")
print(f"{'run':<13} {'seed':>4}  {'validation all':>14} {'val kicks':>10}  {'held-out all':>12} {'held-out kicks':>14}")
for name in sys.argv[1:]:
    for s in range(3):
        real = json.loads((FULL / f"{name}_s{s}" / "results.json").read_text())["real"]
        row = []
        for split in ("validation", "heldout"):
            motions = real[split]["f_calibrated_narrow"]["motions"]
            kicks = [m for m in motions if "_kick_" in m["motion"]]
            row += [f"{sum(m['success'] for m in motions)}/{len(motions)}", f"{sum(m['success'] for m in kicks)}/{len(kicks)}"]
        print(f"{name:<13} {s:>4}  {row[0]:>14} {row[1]:>10}  {row[2]:>12} {row[3]:>14}")
