"""``wresdyn deploy [DATA]``: train tracking skills in the nominal and the corrected simulators and deploy each
zero-shot on the "real" robot (the robot the data was recorded on); see :mod:`wresdyn.experiments.skills`.

Writes ``OUT/report.md`` (the table, gap closed), ``OUT/results.json``, ``OUT/tracking_heldout.png`` and
``OUT/deployed_heldout.usda``; the corrections (``OUT/calibrated``, ``OUT/delta_action``) are fitted on DATA unless
given, and the four policies live in ``OUT/skills/``. Rerunning the same command resumes. Every line printed is also
in ``OUT/deploy.log`` (rsl-rl's tables in each policy's ``train.log``); on a terminal a progress bar per policy shows
the elapsed and remaining time (:mod:`wresdyn.progress`), ``--quiet`` prints nothing.

The sizes are ``DeployConfig`` (``FloorDeployConfig`` with ``--floor``), the task ``--task.*`` is ``SkillConfig``
(``FloorTaskConfig`` with ``--floor``) and the PPO of every policy ``--ppo.*`` is ``SkillPPOConfig``
(:mod:`wresdyn.skills.skill_config`).
"""

from __future__ import annotations

import argparse
from dataclasses import fields

from ..experiments.deploy_config import DeployConfig, FloorDeployConfig
from ..skills.skill_config import FloorTaskConfig, SkillConfig, SkillPPOConfig
from .config_flags import add_config_flags, build_config, given_fields

PPO_FROM_SIZES = ("iterations", "restart_std", "seed", "device")
"""Fields of :class:`SkillPPOConfig` the benchmark sets from the sizes (``iterations``/``finetune``, ``finetune_std``,
``seed``, ``device``): no ``--ppo.*`` flag of their own (the worlds are the sizes' ``num_worlds``, the plants')."""

_STAND, _FLOOR = {f.name for f in fields(SkillConfig)}, {f.name for f in fields(FloorTaskConfig)}
STAND_ONLY = tuple(f.name for f in fields(SkillConfig) if f.name not in _FLOOR)
"""Fields of the task on the stand that the task on the floor lacks."""
FLOOR_ONLY = tuple(f.name for f in fields(FloorTaskConfig) if f.name not in _STAND)
"""Fields of the task on the floor that the task on the stand lacks."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    from ..paths import DEFAULT_DATASET

    p.add_argument("data", nargs="?", default=str(DEFAULT_DATASET),
                   help="dataset the corrections are fitted on; its mismatch is the real robot (default: the shipped one)")
    p.add_argument("--out", default="runs/deploy", help="output folder; rerun to resume (default: runs/deploy)")
    p.add_argument("--calibrated", default=None, metavar="RUN",
                   help="the calibrated robot: a hybrid `wresdyn fit` run (default: fitted into OUT/calibrated)")
    p.add_argument("--delta", default=None, metavar="RUN",
                   help="a delta-action `wresdyn fit --model network --residual delta_action` run "
                        "(default: fitted into OUT/delta_action)")
    p.add_argument("--mismatch", default=None, help="real robot's mismatch (TOML; default: the dataset's)")
    p.add_argument("--floor", action="store_true",
                   help="skills on the floor: the humanoid keeps its balance with a free base (squat, weight shift, "
                        "kick, wave; stepping held out), corrections still fitted on the stand (see "
                        "wresdyn.experiments.skills)")
    p.add_argument("--full", action="store_true",
                   help="the full size, for a GPU (DeployConfig.full, FloorDeployConfig.full; the options below "
                        "still apply)")
    p.add_argument("--no-animation", action="store_true", help="skip the USD animation")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing while deploying (OUT/deploy.log keeps every line; no progress bars)")
    sizes = dict(aliases={"train_per_family": ("--motions",), "heldout_per_family": ("--heldout",),
                          "num_worlds": ("--envs",), "oracle_num_worlds": ("--oracle-envs",)},
                 variants={"--floor": FloorDeployConfig(), "--full": DeployConfig.full(),
                           "--floor --full": FloorDeployConfig.full()})
    add_config_flags(p, DeployConfig(), **sizes,
                     title="sizes (wresdyn.experiments.deploy_config.DeployConfig, FloorDeployConfig with --floor)")
    add_config_flags(p, FloorDeployConfig(), skip=[f.name for f in fields(DeployConfig)],
                     title="on the floor (--floor)")
    add_config_flags(p, SkillConfig(), prefix="task.", skip=STAND_ONLY, variants={"--floor": FloorTaskConfig()},
                     title="the tracking task (wresdyn.skills.skill_config.SkillConfig, FloorTaskConfig with --floor)")
    shared = [f.name for f in fields(SkillConfig) if f.name in _FLOOR]
    add_config_flags(p, SkillConfig(), prefix="task.", skip=shared, title="the task on the stand only (without --floor)")
    add_config_flags(p, FloorTaskConfig(), prefix="task.", skip=shared, title="the task on the floor only (--floor)")
    add_config_flags(p, SkillPPOConfig(), prefix="ppo.", skip=PPO_FROM_SIZES,
                     title="PPO of every policy (wresdyn.skills.skill_config.SkillPPOConfig; worlds, iterations, "
                           "restart noise, seed and device come from the sizes above)")


def config_from_args(args: argparse.Namespace) -> DeployConfig | FloorDeployConfig:
    """The sizes of ``--floor`` and ``--full`` with the flags given applied."""
    from . import UserError

    given = given_fields(args)
    stand = {f.name for f in fields(DeployConfig)}
    for name in (f.name for f in fields(FloorDeployConfig) if f.name not in stand and f.name in given):
        if not args.floor:
            raise UserError(f"--{name.replace('_', '-')} sets the benchmark on the floor; it needs --floor")
    cls = FloorDeployConfig if args.floor else DeployConfig
    return build_config(cls.full() if args.full else cls(), given)


def skill_configs_from_args(args: argparse.Namespace) -> tuple[SkillConfig | FloorTaskConfig, SkillPPOConfig]:
    """The task (:class:`SkillConfig`, :class:`FloorTaskConfig` with ``--floor``) and the PPO of the skills, with the
    ``--task.*`` and ``--ppo.*`` flags given applied."""
    from . import UserError

    task = given_fields(args, "task.")
    other, where = (STAND_ONLY, "on the stand; it has no use with --floor") if args.floor else \
        (FLOOR_ONLY, "on the floor; it needs --floor")
    for name in (n for n in other if n in task):
        raise UserError(f"--task.{name.replace('_', '-')} sets the task {where}")
    return (build_config(FloorTaskConfig() if args.floor else SkillConfig(), task),
            build_config(SkillPPOConfig(), given_fields(args, "ppo.")))


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..data.loading import load_data
    from ..data.mismatch import Mismatch

    cfg = config_from_args(args)
    task, ppo = skill_configs_from_args(args)
    from ..experiments.skills import run_benchmark as bench
    ds, robot = load_data(args.data)
    mismatch = Mismatch.load(args.mismatch) if args.mismatch else None
    from ..progress import Log

    log = Log(Path(args.out) / "deploy.log", quiet=args.quiet)
    log(f"wresdyn deploy: skills {'on the floor' if args.floor else 'on the stand'} on {robot.source.name} ({robot.n_dof} joints), corrections from {args.data}, "
          f"real robot {'from ' + args.mismatch if args.mismatch else 'as recorded in the dataset'} -> {args.out}")
    from ..sim.warmup import compile_kernels

    # the skills replay forward; the corrections not given are fitted here (identification, then gradient fits)
    variants = ("forward",) + (() if args.calibrated else ("param_grads", "grad")) + (() if args.delta else ("grad",))
    compile_kernels(robot, ds.rate_hz, tuple(dict.fromkeys(variants)), device=cfg.device, say=log)
    bench(robot, ds, args.out, cfg, data_path=args.data, calibrated=args.calibrated, delta=args.delta,
          mismatch=mismatch, task=task, ppo=ppo, animation=not args.no_animation, log=log)
    return 0
