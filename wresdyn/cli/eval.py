"""``wresdyn eval RUN``: open-loop replay of held-out and OOD trajectories, PD-only vs PD + the run's residual.

Writes ``metrics.json``, ``report.md``, a Fig. 3-style plot per split and the learning curves (Fig. 4 style,
with ``--compare`` runs overlaid) into ``RUN/eval`` (or ``--out``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import tyro

from ..choices import SolverKind
from .command import Command


@dataclass(frozen=True)
class Eval(Command):
    """``wresdyn eval``: the run, its data and what to replay."""

    run: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN")]
    """Run folder written by `wresdyn train` (or fit, identify)."""
    data: str | None = None
    """Dataset file (default: the one the run was trained on)."""
    robot: str | None = None
    """Robot file (default: the dataset's)."""
    gains: str | None = None
    """Gains config (TOML) by joint-name pattern; replaces the one stored in the dataset."""
    splits: tuple[str, ...] = ("validation", "heldout", "ood")
    """Splits to evaluate (absent splits are skipped)."""
    out: str | None = None
    """Output folder (default: RUN/eval)."""
    solver: SolverKind | None = None
    """Newton solver (default: the one the run was trained with)."""
    device: str = "cpu"
    """cpu or cuda:0."""
    joints: int = 6
    """Joints in the Fig. 3 plot (largest PD-only error first)."""
    compare: tuple[str, ...] = ()
    """Other runs to overlay in the learning curves."""
    ensemble: tuple[str, ...] = ()
    """Other runs averaged with RUN into one model (a seed ensemble): residuals fitted on RUN's physics.json
    are averaged at every step, each seeing the ensemble's replay (same kind, solver and friction law); runs of
    identified physics alone give their parameters' mean. Pass --out: the report is the ensemble's, not RUN's.
    Empty: RUN alone."""


COMMAND = Eval


def run(args: Eval) -> int:
    import json
    from pathlib import Path

    from ..data.loading import load_data
    from ..evaluation.evaluate_run import evaluate_run
    from . import UserError

    cfg_path = Path(args.run) / "config.json"
    if not cfg_path.is_file():
        raise UserError(f"{args.run}: not a run folder (no config.json)")
    data = args.data or json.loads(cfg_path.read_text()).get("data_path")
    if not data:
        raise UserError(f"{args.run}: the run does not record its dataset; pass --data")
    ds, robot = load_data(data, args.robot, args.gains)
    evaluate_run(args.run, ds, robot, list(args.splits), args.out, args.solver, args.device, args.joints,
                 list(args.compare),
                 data_label=str(data), ensemble=list(args.ensemble))
    return 0
