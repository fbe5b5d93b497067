"""``wresdyn train DATA``: learn a residual with PPO on the dataset's training split (resumes a killed run).

Several GPUs: ``torchrun --nproc_per_node N -m wresdyn train DATA --device cuda ...`` (one process per GPU,
``--num-envs`` split across them, rsl-rl's multi-GPU PPO; see :func:`wresdyn.learn.ppo.train`).

Every line printed, and rsl-rl's per-iteration tables, are in ``OUT/train.log``; on a terminal a progress bar shows
the elapsed and remaining time (:mod:`wresdyn.progress`), ``--quiet`` prints nothing."""

from __future__ import annotations

import argparse

from ..choices import Arch, ResidualKind, SolverKind, choices


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("data", help="dataset file (.npz from `wresdyn collect`)")
    p.add_argument("--out", default="runs/residual", help="run folder; a folder with checkpoints is resumed (default: runs/residual)")
    p.add_argument("--robot", default=None, help="robot file (default: the one the dataset was recorded on)")
    p.add_argument("--gains", default=None,
                   help="gains config (TOML) by joint-name pattern; replaces the one stored in the dataset")
    p.add_argument("--residual", choices=choices(ResidualKind), default=None,
                   help="torque (paper) or delta_action (ASAP); default torque")
    p.add_argument("--arch", choices=choices(Arch), default=None,
                   help="policy network: mlp (ELU) or gru (GRU + MLP); default mlp")
    p.add_argument("--iterations", type=int, default=None, help="total PPO iterations of the run")
    p.add_argument("--num-envs", type=int, default=None, help="parallel replay worlds")
    p.add_argument("--steps-per-env", type=int, default=None, help="rollout steps per world per iteration")
    p.add_argument("--horizon", type=int, default=None, help="episode length [steps]")
    p.add_argument("--obs-noise", type=float, default=None,
                   help="noise on the policy's normalised observation during training [stds] (default 0)")
    p.add_argument("--fraction", type=float, default=None, help="residual authority, fraction of each effort limit")
    p.add_argument("--solver", choices=choices(SolverKind), default=None,
                   help="Newton solver for wresdyn.sim.solvers.make_solver (default: auto)")
    p.add_argument("--device", default=None, help="cpu or cuda:0 (default: cpu)")
    p.add_argument("--seed", type=int, default=None, help="seed (default 0)")
    p.add_argument("--save-interval", type=int, default=None, help="checkpoint every N iterations")
    p.add_argument("--physics", default=None, metavar="JSON",
                   help="learn the residual on top of identified physics (physics.json of `wresdyn identify`)")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="override any field of the run configuration (wresdyn.learn.ppo_config.TrainConfig), e.g. "
                        "--set ppo.desired_kl=0.05 --set residual.hidden_dims=128,64; repeatable, applied last")
    p.add_argument("--no-resume", action="store_true", help="refuse to continue an existing run")
    p.add_argument("--eval", action="store_true", help="evaluate held-out and OOD trajectories afterwards (like `wresdyn eval`)")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing while training (OUT/train.log keeps every line and rsl-rl's tables; the "
                        "progress bar is not drawn)")


def config_from_args(args: argparse.Namespace):
    """The default :class:`~wresdyn.learn.ppo_config.TrainConfig` with the flags given on the command line applied.

    Flags and ``--set`` items are applied in one step (``--set`` wins for the same field), so the config's own
    checks, across fields too, see what was asked for as a whole; a refused value is a one-line error."""
    from ..learn.ppo_config import default_config, parse_overrides, set_fields
    from . import UserError

    cfg = default_config()
    flags = {"env.horizon": args.horizon, "env.solver": args.solver, "env.obs_noise": args.obs_noise,
             "env.physics": getattr(args, "physics", None),
             "residual.kind": args.residual, "residual.arch": args.arch, "residual.fraction": args.fraction,
             "ppo.iterations": args.iterations, "ppo.num_envs": args.num_envs,
             "ppo.num_steps_per_env": args.steps_per_env, "ppo.device": args.device, "ppo.seed": args.seed,
             "ppo.save_interval": args.save_interval}
    try:
        given = {k: v for k, v in flags.items() if v is not None}
        return set_fields(cfg, given | parse_overrides(cfg, getattr(args, "overrides", [])))
    except ValueError as e:  # a malformed --set, or a value the config refuses (WresdynError is a ValueError)
        raise UserError(str(e)) from None


def run(args: argparse.Namespace) -> int:
    import json

    from ..learn.ppo import RunError, train
    from ..learn.ppo_runner import Ranks
    from . import UserError

    cfg = config_from_args(args)
    from ..data.loading import load_data

    ds, robot = load_data(args.data, args.robot, args.gains)
    from pathlib import Path

    from ..progress import Log

    main = Ranks.from_env().main  # torchrun: rank 0 reports and evaluates
    log = Log(Path(args.out) / "train.log" if main else None, quiet=args.quiet or not main)
    log(f"training a {cfg.residual.kind} residual ({cfg.residual.arch}) on {len(ds.split('train'))} trajectories of "
          f"{args.data}: {cfg.ppo.iterations} iterations x {cfg.ppo.num_envs} worlds x {cfg.ppo.num_steps_per_env} steps "
          f"-> {args.out}")
    from ..sim.physics import PhysicalParams
    from ..sim.warmup import compile_kernels

    compile_kernels(robot, ds.rate_hz, ("forward",), solver=cfg.env.solver, device=Ranks.from_env().device(cfg.ppo.device),
                    physics=PhysicalParams.load(cfg.env.physics, robot) if cfg.env.physics else None, say=log)
    try:
        summary = train(ds, robot, cfg, args.out, resume=not args.no_resume, data_path=args.data, log=log)
    except RunError as e:
        raise UserError(str(e)) from None
    if not main:
        return 0
    log(json.dumps(summary, indent=2))
    if args.eval:
        from ..evaluation.evaluate_run import evaluate_run

        evaluate_run(args.out, ds, robot, data_label=args.data)
    return 0
