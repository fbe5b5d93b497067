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
                        "wresdyn.experiments.floor_skills; defaults: 3 training motions per family, 4 s, 200 + 60 "
                        "iterations)")
    p.add_argument("--full", action="store_true",
                   help="the full size, for a GPU: 4096 worlds, 16 training / 2 validation / 4 held-out motions per "
                        "family (the options below still apply)")
    p.add_argument("--iterations", type=int, default=None, help="PPO iterations of (a), nominal (default 300)")
    p.add_argument("--finetune", type=int, default=None, help="PPO iterations of each fine-tuning (default 300)")
    p.add_argument("--envs", type=int, default=None, help="parallel worlds of PPO (default 64)")
    p.add_argument("--oracle-envs", type=int, default=None,
                   help="parallel worlds of the oracle on the real robot, MuJoCo C on the CPU (default: --envs; "
                        "--full: 1024)")
    p.add_argument("--oracle-beside", action="store_true", default=None,
                   help="--floor: train the oracle in a process of its own beside (b) and (c) (default on a GPU)")
    p.add_argument("--motions", type=int, default=None, help="training motions per family (default 4)")
    p.add_argument("--heldout", type=int, default=None, help="held-out motions per family (default 2; --floor: 1)")
    p.add_argument("--duration", type=float, default=None, help="length of a motion [s] (default 2; --floor: 4)")
    p.add_argument("--finetune-std", type=float, default=None,
                   help="action noise the fine-tunings (b)-(d) restart from (default: (a)'s own; --full: 0.3)")
    p.add_argument("--seed", type=int, default=0, help="seed of the motions and of PPO")
    p.add_argument("--device", default="cpu", help="cpu or cuda:0 (the real robot always steps on the CPU)")
    p.add_argument("--no-animation", action="store_true", help="skip the USD animation")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing while deploying (OUT/deploy.log keeps every line; no progress bars)")


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace
    from pathlib import Path

    from ..data.loading import load_data
    from ..data.real_robot import Mismatch
    from ..experiments.stand_skills import DeployConfig, run_benchmark

    if args.oracle_beside and not args.floor:
        from . import UserError

        raise UserError("--oracle-beside trains the floor's oracle; it needs --floor")
    if args.floor:
        from ..experiments.floor_skills import FloorDeployConfig, run_floor_benchmark

        cfg = FloorDeployConfig.full() if args.full else FloorDeployConfig()
        bench = run_floor_benchmark
    else:
        cfg = DeployConfig.full() if args.full else DeployConfig()
        bench = run_benchmark
    kw = {k: v for k, v in (("iterations", args.iterations), ("finetune", args.finetune), ("envs", args.envs),
                            ("oracle_envs", args.oracle_envs), ("oracle_beside", args.oracle_beside),
                            ("finetune_std", args.finetune_std),
                            ("train_per_family", args.motions), ("heldout_per_family", args.heldout),
                            ("duration", args.duration)) if v is not None}
    cfg = replace(cfg, seed=args.seed, device=args.device, **kw)
    ds, robot = load_data(args.data)
    mismatch = Mismatch.load(args.mismatch) if args.mismatch else None
    from ..progress import Log

    log = Log(Path(args.out) / "deploy.log", quiet=args.quiet)
    log(f"wresdyn deploy: skills {'on the floor' if args.floor else 'on the stand'} on {robot.source.name} ({robot.n_dof} joints), corrections from {args.data}, "
          f"real robot {'from ' + args.mismatch if args.mismatch else 'as recorded in the dataset'} -> {args.out}")
    from ..sim.warmup import compile_kernels

    # the skills replay forward; the corrections not given are fitted here (identification, then gradient fits)
    variants = ("forward",) + (() if args.calibrated else ("param_grads", "grad")) + (() if args.delta else ("grad",))
    compile_kernels(robot, ds.rate_hz, tuple(dict.fromkeys(variants)), device=args.device, say=log)
    calibrated = Path(args.calibrated) / "physics.json" if args.calibrated else None
    if calibrated is not None and calibrated.is_file():  # the calibrated plant's kernels (its friction is live)
        from ..sim.physics import PhysicalParams

        compile_kernels(robot, ds.rate_hz, ("forward",), device=args.device,
                        physics=PhysicalParams.load(calibrated, robot), say=log)
    bench(robot, ds, args.out, cfg, data_path=args.data, calibrated=args.calibrated, delta=args.delta,
                  mismatch=mismatch, animation=not args.no_animation,
                  log=log)
    return 0
