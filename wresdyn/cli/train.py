"""``wresdyn train DATA``: learn a residual with PPO on the dataset's training split (resumes a killed run).

Several GPUs: ``torchrun --nproc_per_node N -m wresdyn train DATA --device cuda ...`` (one process per GPU,
``--num-envs`` split across them, rsl-rl's multi-GPU PPO; see :func:`wresdyn.learn.ppo.train`).

Every line printed, and rsl-rl's per-iteration tables, are in ``OUT/train.log``; on a terminal a progress bar shows
the elapsed and remaining time (:mod:`wresdyn.progress`), ``--quiet`` prints nothing."""

from __future__ import annotations

import argparse

from ..learn.ppo_config import TrainConfig, default_config, renamed
from .config_flags import add_config_flags, build_config, given_fields, parse_assignments

TRAIN_ALIASES = {"residual.kind": ("--residual",), "residual.arch": ("--arch",), "residual.fraction": ("--fraction",),
                 "ppo.iterations": ("--iterations",), "env.num_worlds": ("--num-envs",),
                 "ppo.num_steps_per_env": ("--steps-per-env",), "env.horizon": ("--horizon",),
                 "env.obs_noise": ("--obs-noise",), "env.solver": ("--solver",),
                 "env.friction_kappa": ("--friction-kappa",), "ppo.device": ("--device",),
                 "ppo.seed": ("--seed",), "ppo.save_interval": ("--save-interval",), "env.physics": ("--physics",)}
"""The short spellings of the run configuration's common flags, as in earlier releases."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("data", help="dataset file (.npz from `wresdyn collect`)")
    p.add_argument("--out", default="runs/residual", help="run folder; a folder with checkpoints is resumed (default: runs/residual)")
    p.add_argument("--robot", default=None, help="robot file (default: the one the dataset was recorded on)")
    p.add_argument("--gains", default=None,
                   help="gains config (TOML) by joint-name pattern; replaces the one stored in the dataset")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="set any field of the run configuration by its dotted name, e.g. --set ppo.desired_kl=0.05 "
                        "--set residual.hidden_dims=128,64 (the same as --ppo.desired-kl 0.05); repeatable, applied "
                        "after the flags")
    p.add_argument("--no-resume", action="store_true", help="refuse to continue an existing run")
    p.add_argument("--eval", action="store_true", help="evaluate held-out and OOD trajectories afterwards (like `wresdyn eval`)")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing while training (OUT/train.log keeps every line and rsl-rl's tables; the "
                        "progress bar is not drawn)")
    add_config_flags(p, default_config(), aliases=TRAIN_ALIASES,
                     title="run configuration (wresdyn.learn.ppo_config.TrainConfig)")


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """The default :class:`~wresdyn.learn.ppo_config.TrainConfig` with the flags given on the command line applied.

    Flags and ``--set`` items are applied in one step (``--set`` wins for the same field), so the config's own
    checks, across fields too, see what was asked for as a whole; a refused value is a one-line error."""
    overrides = parse_assignments(TrainConfig, [renamed(i) for i in getattr(args, "overrides", [])])
    return build_config(default_config(), given_fields(args) | overrides)


def run(args: argparse.Namespace) -> int:
    import json

    from ..learn.ppo import RunError, train
    from ..learn.ppo_runner import Ranks
    from . import UserError

    cfg = config_from_args(args)
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
        summary = train(ds, robot, cfg, args.out, resume=not args.no_resume, data_path=args.data, log=log,
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
