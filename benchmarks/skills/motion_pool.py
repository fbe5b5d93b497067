"""Time the floor motions' draw and screening serially and in a process pool, and check the two sets are the same
bit for bit: ``python benchmarks/skills/motion_pool.py --workers N``. Prints the wall-clock of ``make_motions`` (the
pool's start included: each worker imports the package and loads the robot) and a SHA-256 over every motion's
arrays, name, family, screen report and parameters, which two runs compare."""

from __future__ import annotations

import argparse
import hashlib
import json
import time

import numpy as np

from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.skills.motions import make_motions


def digest(motions) -> str:
    """SHA-256 of a motion set: every motion's arrays' bytes, shapes and dtypes, and its other fields as JSON."""
    h = hashlib.sha256()
    for split, ms in motions.splits.items():
        for m in ms:
            h.update(json.dumps([split, m.name, m.family, m.screen, m.params], sort_keys=True, default=str).encode())
            for a in (m.q, m.qd, m.feet, m.base, m.planted):
                h.update(f"{a.dtype}{a.shape}".encode() + np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--workers", type=int, default=1)
    p.add_argument("--per-family", type=int, default=2, help="validation motions per training family")
    p.add_argument("--rate", type=float, default=500.0, help="sample rate [Hz] (the shipped dataset's)")
    p.add_argument("--duration", type=float, default=4.0)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    stand = load_robot(DEFAULT_ROBOT)
    floating = load_robot(stand.source, base="floating")
    t0 = time.perf_counter()
    ms = make_motions(stand, {"validation": a.per_family}, a.duration, a.rate, a.seed, floating=floating,
                      workers=a.workers)
    wall = time.perf_counter() - t0
    print(json.dumps({"workers": a.workers, "motions": len(ms["validation"]), "make_motions_s": round(wall, 2),
                      "screen": [m.screen for m in ms["validation"]], "sha256": digest(ms)}))


if __name__ == "__main__":
    main()
