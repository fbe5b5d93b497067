"""``wresdyn migrate OLD.npz --out NEW.npz [--validation K]``: rewrite a schema-1 dataset file as schema 2.

With ``--validation K``, a dataset recorded by ``wresdyn collect`` on the simulated real robot gets K validation
trajectories recorded exactly as ``collect`` would have (and their PD-only gap when the file stores the
others'); a dataset of real logs gets its last K training trajectories moved to validation instead
(:mod:`wresdyn.data.schema_migration`). The new file is written atomically; an existing one is kept unless ``--force``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated

import tyro

from .command import Command


@dataclass(frozen=True)
class Migrate(Command):
    """``wresdyn migrate``: the old file, the new one, and the validation split to add."""

    data: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="DATA")]
    """Schema-1 dataset file (.npz)."""
    out: str
    """The schema-2 file to write."""
    validation: int = 0
    """Validation trajectories: recorded on the simulated real robot, or moved from the end of train for real
    logs."""
    force: bool = False
    """Overwrite --out if it exists."""
    robot: str | None = None
    """Robot file to record on (default: the dataset's)."""
    gains: str | None = None
    """Gains config (TOML) by joint-name pattern; replaces the one stored in the dataset."""
    gap: bool = True
    """Replay the new validation split PD-only in Newton and store its gap (--no-gap skips it)."""

    def __post_init__(self) -> None:
        if self.validation < 0:
            raise ValueError(f"--validation must be >= 0, not {self.validation}")


COMMAND = Migrate


def _say(line: str) -> None:
    print(line, flush=True)


def run(args: Migrate) -> int:
    from pathlib import Path

    from ..data.dataset import SCHEMA_VERSION, SPLITS, read_header
    from ..data.loading import dataset_robot
    from ..data.schema_migration import migrate
    from . import UserError

    out = Path(args.out)
    if out.is_dir():
        raise UserError(f"{out}: --out is a folder; give the file to write")
    if out.exists() and not args.force:
        raise UserError(f"{out}: exists; pass --force to overwrite it")
    robot = None
    if args.validation and (args.robot or args.gains):
        header = read_header(args.data)
        gains = args.gains if args.gains is not None else (header["gains"] or {}).get("config")
        robot = dataset_robot(header["robot_file"], args.robot, gains)
    m = migrate(args.data, args.validation, robot, progress=_say)
    ds = m.dataset
    if m.how == "recorded":
        _say(f"recorded {len(m.names)} validation trajectories ({', '.join(m.names)}), seeds and robot as collect's")
    elif m.how == "moved from train":
        _say(f"not recorded by `wresdyn collect` on the simulated robot: moved the last {len(m.names)} training "
             f"trajectories to validation ({', '.join(m.names)}); {len(ds.split('train'))} stay in train")
    gaps = ds.meta.get("pd_only_gap")
    if m.names and isinstance(gaps, dict) and args.gap:
        from ..evaluation.open_loop import pd_gap

        robot = m.robot or dataset_robot(ds.robot_file, args.robot,
                                         args.gains if args.gains is not None else ds.gains_config)
        _say(f"replaying {len(m.names)} validation trajectories PD-only in Newton (nominal robot)")
        mapped = ds.for_robot(robot, str(args.data))
        g = pd_gap(robot, mapped.split("validation"), ds.rate_hz, weights=mapped.fit_weights())
        _say(f"  PD-only vs real on validation: mean |dq| {g['mean']:.4f} +- {g['std']:.4f} rad")
        ds.meta["pd_only_gap"] = {"validation": g, **{k: v for k, v in gaps.items() if k != "validation"}}
    ds.save(out)
    counts = ", ".join(f"{s} {len(ds.split(s))}" for s in SPLITS)
    _say(f"wrote {out} (schema {m.from_version} -> {SCHEMA_VERSION}: {counts})")
    return 0
