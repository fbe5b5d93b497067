"""Compare two `wresdyn fit` run folders: identified physics (identify/physics.json) and both curves, entry by entry.

usage: python compare_runs.py BEFORE_RUN AFTER_RUN
"""
import json
import sys
from pathlib import Path

import numpy as np


def flat(x, prefix=""):
    if isinstance(x, dict):
        for k, v in x.items():
            yield from flat(v, f"{prefix}.{k}" if prefix else str(k))
    elif isinstance(x, list) and x and not isinstance(x[0], (int, float, type(None))):
        for i, v in enumerate(x):
            yield from flat(v, f"{prefix}[{i}]")
    else:
        yield prefix, x


def compare(a_path: Path, b_path: Path, skip=("wall",)) -> None:
    a, b = dict(flat(json.loads(a_path.read_text()))), dict(flat(json.loads(b_path.read_text())))
    keys = [k for k in a if not any(s in k.split(".")[-1] for s in skip)]
    equal, worst = 0, (0.0, None)
    for k in keys:
        x, y = a[k], b.get(k)
        if x == y:
            equal += 1
            continue
        try:
            xa, ya = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
            rel = float(np.nanmax(np.abs(xa - ya) / np.maximum(np.abs(xa), 1e-12)))
        except (TypeError, ValueError):
            rel = float("inf")
        if rel > worst[0]:
            worst = (rel, k)
    print(f"{a_path.relative_to(a_path.parents[1]) if 'identify' in str(a_path) else a_path.name}: "
          f"{equal}/{len(keys)} entries bit-equal (wall-clock entries skipped); largest relative difference "
          f"{worst[0]:.3g} at {worst[1]}")


if __name__ == "__main__":
    before, after = Path(sys.argv[1]), Path(sys.argv[2])
    for rel in ("identify/physics.json", "identify/curve.json", "physics.json", "curve.json"):
        compare(before / rel, after / rel)
