"""Compare two fit run folders' numbers: every JSON leaf of the files below, less the wall-clocks and run paths.

    python compare.py BEFORE_RUN AFTER_RUN
"""
import json
import sys

FILES = ("train_summary.json", "eval/metrics.json", "curve.json", "identify/curve.json", "identify/physics.json",
         "residual.json")
SKIP = ("wall", "wall_s", "residual_wall_s", "identify_wall_s", "run", "physics")  # clocks; paths of the run folder


def leaves(d, p=""):
    if isinstance(d, dict):
        return {k: v for key, val in d.items() for k, v in leaves(val, f"{p}/{key}").items()}
    if isinstance(d, list):
        return {k: v for i, val in enumerate(d) for k, v in leaves(val, f"{p}[{i}]").items()}
    return {p: d}


bad = 0
for f in FILES:
    a, b = (leaves(json.load(open(f"{run}/{f}"))) for run in sys.argv[1:3])
    keys = [k for k in sorted(set(a) | set(b)) if k.rsplit("/", 1)[-1] not in SKIP]
    diff = [k for k in keys if a.get(k) != b.get(k)]
    bad += len(diff)
    print(f"{f}: {len(keys)} values compared, {len(diff)} differ {diff[:5]}")
print("identical" if bad == 0 else f"{bad} differ")
