"""``wresdyn train DATA``: learn a residual with PPO on the dataset's training split (resumes a killed run).

Several GPUs: ``torchrun --nproc_per_node N -m wresdyn train DATA --ppo.device cuda ...`` (one process per GPU,
``--env.num-worlds`` split across them, rsl-rl's multi-GPU PPO; see :func:`wresdyn.ppo.trainer.train`).

Every line printed, and rsl-rl's per-iteration tables, are in ``OUT/train.log``; on a terminal a progress bar shows
the elapsed and remaining time (:mod:`wresdyn.progress`), ``--quiet`` prints nothing."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

import tyro

from ..ppo.ppo_config import TrainConfig, default_config
from .command import FLAT, Command


@dataclass(frozen=True)
class Train(Command):
    """``wresdyn train``: the dataset, the run folder and the run configuration (``--env.*``, ``--residual.*``,
    ``--rewards.*``, ``--ppo.*``)."""

    data: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="DATA")]
    """Dataset file (.npz from `wresdyn collect`)."""
    out: str = "runs/residual"
    """Run folder; a folder with checkpoints is resumed."""
    robot: str | None = None
    """Robot file (default: the one the dataset was recorded on)."""
    gains: str | None = None
    """Gains config (TOML) by joint-name pattern; replaces the one stored in the dataset."""
    resume: bool = True
    """Continue an existing run (--no-resume refuses to)."""
    eval: bool = False
    """Evaluate held-out and OOD trajectories afterwards (like `wresdyn eval`)."""
    quiet: bool = False
    """Print nothing while training (OUT/train.log keeps every line and rsl-rl's tables; the progress bar is not
    drawn)."""
    config: Annotated[TrainConfig, FLAT] = field(default_factory=default_config)
    """The run configuration."""


COMMAND = Train


def run(args: Train) -> int:
    import json

    from ..ppo.trainer import RunError, train
    from ..ppo.runner import Ranks
    from . import UserError

    cfg = args.config
    try:  # worlds that do not split over torchrun's processes: refused on every rank before the data and kernels load
        Ranks.from_env().num_worlds(cfg.env.num_worlds)
    except RunError as e:
        raise UserError(str(e)) from None
    from ..data.loading import load_data

    ds, robot = load_data(args.data, args.robot, args.gains)
    from pathlib import Path

    from ..progress import Log

    main = Ranks.from_env().main  # torchrun: rank 0 reports and evaluates
    log = Log(Path(args.out) / "train.log" if main else None, quiet=args.quiet or not main)
    log(f"training a {cfg.residual.kind} residual ({cfg.residual.arch}) on {len(ds.split('train'))} trajectories of "
          f"{args.data}: {cfg.ppo.iterations} iterations x {cfg.env.num_worlds} worlds x {cfg.ppo.num_steps_per_env} steps "
          f"-> {args.out}")
    from ..sim.physics import PhysicalParams
    from ..sim.warmup import compile_kernels

    physics = PhysicalParams.load(cfg.env.physics, robot) if cfg.env.physics else None
    compile_kernels(robot, ds.rate_hz, ("forward",), solver=cfg.env.solver, device=Ranks.from_env().device(cfg.ppo.device),
                    say=log)
    try:
        summary = train(ds, robot, cfg, args.out, resume=args.resume, data_path=args.data, log=log,
                        physics=physics)
    except RunError as e:
        raise UserError(str(e)) from None
    if not main:
        return 0
    log(json.dumps(summary, indent=2))
    if args.eval:
        from ..evaluation.evaluate_run import evaluate_run

        evaluate_run(args.out, ds, robot, data_label=args.data)
    return 0
