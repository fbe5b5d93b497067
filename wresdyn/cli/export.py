"""``wresdyn export RUN``: the calibrated robot as USD layers over the robot file, Newton actuators and the residual.

Writes ``robot.usda`` (identified physics as the attributes Newton's importer reads), ``actuated.usda`` (the drive
path as ``newton.actuators`` prims and the residual network), ``residual.pt2``/``.onnx``, ``physics.json`` into
``RUN/export`` (or ``--out``); see :mod:`wresdyn.export.usd`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import tyro

from .command import Command


@dataclass(frozen=True)
class Export(Command):
    """``wresdyn export``: the run and where its calibrated robot goes."""

    run: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN")]
    """Run folder written by `wresdyn fit` (the hybrid: identified physics + residual)."""
    out: str | None = None
    """Output folder (default: RUN/export)."""
    force: bool = False
    """Replace an existing output folder."""
    physics_only: bool = False
    """Export the run's physics without a residual (e.g. a `wresdyn identify` run)."""
    data: str | None = None
    """Dataset file (default: the one the run was trained on)."""
    gains: str | None = None
    """Gains config (TOML) by joint-name pattern; replaces the one stored in the dataset."""


COMMAND = Export


def run(args: Export) -> int:
    from ..export.usd import export_run

    out = export_run(args.run, args.out, force=args.force, physics_only=args.physics_only, data=args.data,
                     gains=args.gains)
    print(f"wrote {out}/robot.usda (identified physics) and {out}/actuated.usda (Newton actuators"
          f"{' + residual' if (out / 'residual.pt2').exists() else ''})")
    return 0
