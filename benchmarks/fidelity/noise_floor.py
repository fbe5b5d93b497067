"""The floor no model can beat: the "real" robot against itself, re-recorded with another sensor-noise seed.

Every trajectory of a split is executed again on ``RealRobot`` (same robot, same mismatch, same commands, same
start) with a different noise generator; the mean |Δq| between the two recordings is the error a perfect model of
the physics would still show against the dataset (sensor noise and quantisation of both). Prints the floor per split
and, given run folders with ``eval/metrics.json``, the fraction of the PD-only gap each closes toward the floor:
(PD − model) / (PD − floor).

    python benchmarks/fidelity/noise_floor.py data/dataset.npz [RUN ...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data")
    ap.add_argument("runs", nargs="*", help="run folders with eval/metrics.json")
    ap.add_argument("--seed", type=int, default=12345, help="seed of the second recording's noise")
    args = ap.parse_args()

    from wresdyn.data.loading import load_data
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot

    ds, robot = load_data(args.data, None)
    if not ds.mismatch:
        raise SystemExit(f"{args.data}: no mismatch recorded (hardware logs): the floor needs the simulated robot")
    real = RealRobot(robot, Mismatch.from_dict(ds.mismatch), ds.rate_hz)
    settle = float(ds.meta.get("real_robot", {}).get("settle_s", 0.5))
    floor = {}
    for split in ("validation", "heldout", "ood"):
        trajs = ds.split(split)
        if not trajs:
            continue
        errs = []
        for i, t in enumerate(trajs):
            q, _, _ = real.record(t.q_cmd, np.random.default_rng([args.seed, i]), settle=settle)
            errs.append(np.abs(np.asarray(q, dtype=np.float32).astype(np.float64) - t.q))
        floor[split] = float(np.concatenate(errs).mean())
        print(f"{split:<10} floor mean |dq| {floor[split]:.5f} rad ({len(trajs)} trajectories re-recorded)")
    for run in args.runs:
        m = json.loads((Path(run) / "eval" / "metrics.json").read_text())["splits"]
        cells = []
        for split, f in floor.items():
            if split not in m or not m[split]["pd_residual"]:
                continue
            pd, model = m[split]["pd_only"]["mean_abs_dq"], m[split]["pd_residual"]["mean_abs_dq"]
            cells.append(f"{split} {model:.4f} rad, {pd / model:.2f}x, gap closed {(pd - model) / (pd - f):.1%}")
        print(f"{run}: " + "; ".join(cells))


if __name__ == "__main__":
    main()
