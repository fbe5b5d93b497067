"""``wresdyn export RUN``: the calibrated robot as USD layers over the robot file, Newton actuators and the residual.

Writes ``robot.usda`` (identified physics as the attributes Newton's importer reads), ``actuated.usda`` (the drive
path as ``newton.actuators`` prims and the residual network), ``residual.pt2``/``.onnx``, ``physics.json`` into
``RUN/export`` (or ``--out``); see :mod:`wresdyn.export.usd`. ``--format mjcf`` (the default for MJCF and URDF
robots) writes ``robot.xml`` for plain MuJoCo, ``residual.onnx`` and ``play_mujoco.py`` instead; see
:mod:`wresdyn.export.mjcf`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Annotated, Literal

import tyro

from ..errors import WresdynError

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
    format: Literal["usd", "mjcf"] | None = None
    """`usd` (layers over a USD robot file, Newton actuators) or `mjcf` (robot.xml for plain MuJoCo, any robot
    file); default: usd for a USD robot, mjcf for an MJCF or URDF one."""


COMMAND = Export


def run(args: Export) -> int:
    from ..export.usd import export_run

    if (args.format or _default_format(args)) == "mjcf":
        from ..export.mjcf import export_mjcf

        out = export_mjcf(args.run, args.out, force=args.force, physics_only=args.physics_only, data=args.data,
                          gains=args.gains)
        trip = json.loads((out / "mjcf_report.json").read_text()).get("round_trip")
        extra = " + residual.onnx" if (out / "residual.onnx").exists() else ""
        print(f"wrote {out}/robot.xml (identified physics as MuJoCo actuators){extra}"
              + ("" if trip is None else f"; held-out mean |dq| wresdyn {trip['wresdyn']:.3e} rad, MuJoCo "
                 f"{trip['mujoco']:.3e} rad"))
        return 0
    out = export_run(args.run, args.out, force=args.force, physics_only=args.physics_only, data=args.data,
                     gains=args.gains)
    print(f"wrote {out}/robot.usda (identified physics) and {out}/actuated.usda (Newton actuators"
          f"{' + residual' if (out / 'residual.pt2').exists() else ''})")
    return 0


def _default_format(args: Export) -> str:
    """usd for a run whose dataset's robot file is USD, else mjcf (an unreadable run: usd, whose checks say why)."""
    from pathlib import Path

    try:
        data = args.data or json.loads((Path(args.run) / "config.json").read_text()).get("data_path")
        from ..data.dataset import load_dataset

        robot_file = str(load_dataset(data).robot_file) if data else ""
    except (OSError, ValueError, WresdynError):
        return "usd"
    return "usd" if robot_file.lower().endswith((".usd", ".usda", ".usdc")) or not robot_file else "mjcf"
