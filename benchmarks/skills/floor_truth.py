"""Identified against true joint parameters of a calibrated robot, per joint: the ratio identified/true of the drive
effort limit, PD gains kp and kd, Coulomb friction, viscous damping, armature and actuation delay, the identified values
read from ``physics.json`` (a ``wresdyn fit`` run, or a folder of the deploy's corrections holding ``calibrated/``), the
true ones from the real robot the dataset was recorded on (:meth:`~wresdyn.data.real_robot.RealRobot.physics` of its
mismatch). Nothing is simulated or scored: the dataset gives the mismatch only.

    python benchmarks/skills/floor_truth.py CORRECTIONS DATA [--stage identify]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

FIELDS = ("effort", "kp", "kd", "friction", "damping", "armature", "delay")
"""The per-joint parameters compared, in the order printed."""


def physics_file(corrections: Path, stage: str) -> Path:
    """The ``physics.json`` of ``corrections``: a run folder holding one, or a deploy's corrections folder whose
    ``calibrated/`` does; ``stage`` ``identify`` reads the identification's, before the residual's fit refines it."""
    for run in (corrections, corrections / "calibrated"):
        path = run / "identify" / "physics.json" if stage == "identify" else run / "physics.json"
        if path.is_file():
            return path
    raise SystemExit(f"error: no {stage} physics.json in {corrections} or {corrections / 'calibrated'}")


def ratios(identified: dict, truth, names: list[str]) -> dict[str, np.ndarray]:
    """``{field: identified / true}`` per joint of ``names`` (NaN where the truth is zero)."""
    if list(identified["joint_names"]) != list(names):
        raise SystemExit("error: the calibrated robot's joints are not the dataset's robot's")
    out = {}
    for field in FIELDS:
        true = np.broadcast_to(np.asarray(getattr(truth, field), float).reshape(-1), (len(names),))
        ident = np.broadcast_to(np.asarray(identified[field], float).reshape(-1), (len(names),))
        out[field] = ident / np.where(true == 0.0, np.nan, true)
    return out


def table(names: list[str], r: dict[str, np.ndarray]) -> str:
    """The ratios as a text table: a row per joint, a column per field, then the median and range over joints."""
    short = [n.replace("left_", "L_").replace("right_", "R_") for n in names]
    lines = [f"{'joint':18s}" + "".join(f"{f:>10s}" for f in FIELDS)]
    lines += [f"{n:18s}" + "".join(f"{r[f][j]:10.2f}" for f in FIELDS) for j, n in enumerate(short)]
    for label, fn in (("median", np.nanmedian), ("min", np.nanmin), ("max", np.nanmax)):
        lines.append(f"{label:18s}" + "".join(f"{fn(r[f]):10.2f}" for f in FIELDS))
    return "\n".join(lines)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("corrections", type=Path, help="a calibrated run folder, or a folder holding calibrated/")
    p.add_argument("data", help="the dataset the corrections were fitted on (its mismatch is the truth)")
    p.add_argument("--stage", choices=("final", "identify"), default="final",
                   help="the calibrated robot's final physics (default) or its identification's")
    args = p.parse_args()

    from wresdyn.data.loading import load_data
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot

    path = physics_file(args.corrections, args.stage)
    ds, robot = load_data(args.data, None, None)
    truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch, "the dataset's mismatch"), float(ds.rate_hz)).physics()
    identified = json.loads(path.read_text())
    print(f"identified/true per joint: {path} against the real robot of {args.data}")
    print(table(list(robot.joint_names), ratios(identified, truth, list(robot.joint_names))))


if __name__ == "__main__":
    main()
