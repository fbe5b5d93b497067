"""``wresdyn export RUN``: the calibrated robot as USD layers over the robot file, Newton actuators and the residual.

Writes ``robot.usda`` (identified physics as the attributes Newton's importer reads), ``actuated.usda`` (the drive
path as ``newton.actuators`` prims and the residual network), ``residual.pt2``/``.onnx``, ``physics.json`` into
``RUN/export`` (or ``--out``); see :mod:`wresdyn.export.usd`.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("run", help="run folder written by `wresdyn fit` (the hybrid: identified physics + residual)")
    p.add_argument("--out", default=None, help="output folder (default: RUN/export)")
    p.add_argument("--force", action="store_true", help="replace an existing output folder")
    p.add_argument("--physics-only", action="store_true",
                   help="export the run's physics without a residual (e.g. a `wresdyn identify` run)")
    p.add_argument("--data", default=None, help="dataset file (default: the one the run was trained on)")
    p.add_argument("--gains", default=None,
                   help="gains config (TOML) by joint-name pattern; replaces the one stored in the dataset")


def run(args: argparse.Namespace) -> int:
    from ..export.usd import export_run

    out = export_run(args.run, args.out, force=args.force, physics_only=args.physics_only, data=args.data,
                     gains=args.gains)
    print(f"wrote {out}/robot.usda (identified physics) and {out}/actuated.usda (Newton actuators"
          f"{' + residual' if (out / 'residual.pt2').exists() else ''})")
    return 0
