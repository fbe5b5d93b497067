"""``wresdyn train DATA``: learn a residual with PPO on the dataset's training split (resumes a killed run)."""

from __future__ import annotations

import argparse

KINDS = ("torque", "delta_action")  # wresdyn.learn.residual.KINDS, repeated so --help does not import torch
ARCHS = ("mlp", "gru")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("data", help="dataset file (.npz from `wresdyn collect`)")
    p.add_argument("--out", default="runs/residual", help="run folder; a folder with checkpoints is resumed (default: runs/residual)")
    p.add_argument("--robot", default=None, help="robot file (default: the one the dataset was recorded on)")
    p.add_argument("--residual", choices=KINDS, default=None, help="torque (paper) or delta_action (ASAP); default torque")
    p.add_argument("--arch", choices=ARCHS, default=None, help="policy network: mlp (ELU) or gru (GRU + MLP); default mlp")
    p.add_argument("--iterations", type=int, default=None, help="total PPO iterations of the run")
    p.add_argument("--num-envs", type=int, default=None, help="parallel replay worlds")
    p.add_argument("--steps-per-env", type=int, default=None, help="rollout steps per world per iteration")
    p.add_argument("--horizon", type=int, default=None, help="episode length [steps]")
    p.add_argument("--obs-noise", type=float, default=None,
                   help="noise on the policy's normalised observation during training [stds] (default 0)")
    p.add_argument("--fraction", type=float, default=None, help="residual authority, fraction of each effort limit")
    p.add_argument("--solver", default=None, help="Newton solver for wresdyn.sim.solvers.make_solver (default: auto)")
    p.add_argument("--device", default=None, help="cpu or cuda:0 (default: cpu)")
    p.add_argument("--seed", type=int, default=None, help="seed (default 0)")
    p.add_argument("--save-interval", type=int, default=None, help="checkpoint every N iterations")
    p.add_argument("--set", dest="overrides", action="append", default=[], metavar="SECTION.FIELD=VALUE",
                   help="override any field of the run configuration (wresdyn.learn.ppo.TrainConfig), e.g. "
                        "--set ppo.desired_kl=0.05 --set residual.hidden_dims=128,64; repeatable, applied last")
    p.add_argument("--no-resume", action="store_true", help="refuse to continue an existing run")
    p.add_argument("--eval", action="store_true", help="evaluate held-out and OOD trajectories afterwards (like `wresdyn eval`)")


def config_from_args(args: argparse.Namespace):
    """The default :class:`~wresdyn.learn.ppo.TrainConfig` with the flags given on the command line applied."""
    from dataclasses import replace

    from ..learn.ppo import apply_overrides, default_config
    from . import UserError

    cfg = default_config()
    env = {k: v for k, v in (("horizon", args.horizon), ("solver", args.solver), ("obs_noise", args.obs_noise))
           if v is not None}
    res = {k: v for k, v in (("kind", args.residual), ("arch", args.arch), ("fraction", args.fraction)) if v is not None}
    ppo = {k: v for k, v in (("iterations", args.iterations), ("num_envs", args.num_envs),
                             ("num_steps_per_env", args.steps_per_env), ("device", args.device), ("seed", args.seed),
                             ("save_interval", args.save_interval)) if v is not None}
    cfg = replace(cfg, env=replace(cfg.env, **env), residual=replace(cfg.residual, **res), ppo=replace(cfg.ppo, **ppo))
    try:
        return apply_overrides(cfg, getattr(args, "overrides", []))
    except ValueError as e:
        raise UserError(str(e)) from None



def run(args: argparse.Namespace) -> int:
    import json

    from ..learn.ppo import RunError, train
    from . import UserError

    cfg = config_from_args(args)
    if cfg.ppo.iterations < 1 or cfg.ppo.num_envs < 1 or cfg.ppo.num_steps_per_env < 1 or cfg.env.horizon < 1:
        raise UserError("--iterations, --num-envs, --steps-per-env and --horizon must be >= 1")
    if not 0.0 < cfg.residual.fraction:
        raise UserError("--fraction must be > 0")
    from ..data.loading import load_data

    ds, robot = load_data(args.data, args.robot)
    print(f"training a {cfg.residual.kind} residual ({cfg.residual.arch}) on {len(ds.split('train'))} trajectories of "
          f"{args.data}: {cfg.ppo.iterations} iterations x {cfg.ppo.num_envs} worlds x {cfg.ppo.num_steps_per_env} steps "
          f"-> {args.out}", flush=True)
    try:
        summary = train(ds, robot, cfg, args.out, resume=not args.no_resume, data_path=args.data)
    except RunError as e:
        raise UserError(str(e)) from None
    print(json.dumps(summary, indent=2))
    if args.eval:
        from ..evaluation.runs import evaluate_run

        evaluate_run(args.out, ds, robot, data_label=args.data)
    return 0
