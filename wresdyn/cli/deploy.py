"""``wresdyn deploy [DATA]``: train tracking skills in the nominal and the corrected simulators and deploy each
zero-shot on the "real" robot (the robot the data was recorded on); see :mod:`wresdyn.experiments.stand_skills`.

Writes ``OUT/report.md`` (the table, gap closed), ``OUT/results.json``, ``OUT/tracking_heldout.png`` and
``OUT/deployed_heldout.usda``; the corrections (``OUT/calibrated``, ``OUT/delta_action``) are fitted on DATA unless
given, and the four policies live in ``OUT/skills/``. Rerunning the same command resumes. Every line printed is also
in ``OUT/deploy.log`` (rsl-rl's tables in each policy's ``train.log``); on a terminal a progress bar per policy shows
the elapsed and remaining time (:mod:`wresdyn.progress`), ``--quiet`` prints nothing.
"""

from __future__ import annotations

import argparse
from dataclasses import fields

from ..experiments.deploy_config import DeployConfig, FloorDeployConfig
from .config_flags import add_config_flags, build_config, given_fields


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
                        "wresdyn.experiments.floor_skills)")
    p.add_argument("--full", action="store_true",
                   help="the full size, for a GPU (DeployConfig.full, FloorDeployConfig.full; the options below "
                        "still apply)")
    p.add_argument("--no-animation", action="store_true", help="skip the USD animation")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing while deploying (OUT/deploy.log keeps every line; no progress bars)")
    sizes = dict(aliases={"train_per_family": ("--motions",), "heldout_per_family": ("--heldout",)},
                 variants={"--floor": FloorDeployConfig(), "--full": DeployConfig.full(),
                           "--floor --full": FloorDeployConfig.full()})
    add_config_flags(p, DeployConfig(), **sizes,
                     title="sizes (wresdyn.experiments.deploy_config.DeployConfig, FloorDeployConfig with --floor)")
    add_config_flags(p, FloorDeployConfig(), skip=[f.name for f in fields(DeployConfig)],
                     title="on the floor (--floor)")


def config_from_args(args: argparse.Namespace) -> DeployConfig | FloorDeployConfig:
    """The sizes of ``--floor`` and ``--full`` with the flags given applied."""
    from . import UserError

    given = given_fields(args)
    if "oracle_beside" in given and not args.floor:
        raise UserError("--oracle-beside trains the floor's oracle; it needs --floor")
    cls = FloorDeployConfig if args.floor else DeployConfig
    return build_config(cls.full() if args.full else cls(), given)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from ..data.loading import load_data
    from ..data.real_robot import Mismatch

    cfg = config_from_args(args)
    if args.floor:
        from ..experiments.floor_skills import run_floor_benchmark as bench
    else:
        from ..experiments.stand_skills import run_benchmark as bench
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
    calibrated = Path(args.calibrated) / "physics.json" if args.calibrated else None
    if calibrated is not None and calibrated.is_file():  # the calibrated plant's kernels (its friction is live)
        from ..sim.physics import PhysicalParams

        compile_kernels(robot, ds.rate_hz, ("forward",), device=cfg.device,
                        physics=PhysicalParams.load(calibrated, robot), say=log)
    bench(robot, ds, args.out, cfg, data_path=args.data, calibrated=args.calibrated, delta=args.delta,
                  mismatch=mismatch, animation=not args.no_animation,
                  log=log)
    return 0
