"""``wresdyn identify DATA``: identify the simulator's own physical parameters through the differentiable solver.

Grey-box system identification (:mod:`wresdyn.learn.sysid`): per joint PD gains, armature, viscous damping, dry
friction with stiction, effort limit and command delay; per link mass, centre of mass and inertia. The run
folder holds ``physics.json`` (the calibrated robot's parameters, JSON), ``config.json``, ``checkpoint.pt``
(resumed when present; a changed config is refused), ``curve.json`` and ``identify.log`` (every line printed;
``--quiet`` prints none); with ``--eval`` the calibrated model is replayed on every split (``eval/report.md``)
and, for data recorded on the simulated real robot, the identified values are compared with the truth
(``identification.md``). ``wresdyn fit DATA --physics RUN/physics.json``
then learns a residual on top (the hybrid model).
"""

from __future__ import annotations

import argparse

from ..choices import SolverKind, choices


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("data", help="dataset file (.npz from `wresdyn collect`)")
    p.add_argument("--out", default="runs/identify", help="run folder (default: runs/identify)")
    p.add_argument("--robot", default=None, help="robot file (default: the one the dataset was recorded on)")
    p.add_argument("--gains", default=None,
                   help="gains config (TOML) by joint-name pattern; replaces the one stored in the dataset")
    p.add_argument("--iterations", type=int, default=None, help="optimiser steps")
    p.add_argument("--windows", type=int, default=None, help="parallel windows (worlds) per step")
    p.add_argument("--fit", default=None, help="fields to identify, comma separated (default: all of "
                   "kp,kd,armature,damping,friction,effort,delay,bodies)")
    p.add_argument("--delay-grid", default=None, metavar="STEPS",
                   help="command delays [simulation steps] to search, one for every joint, before the gradient fit "
                        "refines them, e.g. 0,10,25,50 (for drives that lag far more than a window sees; default off)")
    p.add_argument("--gain-grid", default=None, metavar="FACTORS",
                   help=GAIN_GRID_HELP)
    p.add_argument("--refine", type=int, default=None, metavar="STEPS",
                   help="L-BFGS steps after the Adam iterations, on fixed training windows, each validated "
                        "(default 0: off; 8 take about a minute on 2 cores)")
    p.add_argument("--solver", choices=choices(SolverKind), default=None, help="simulation solver (default: auto)")
    p.add_argument("--device", default="cpu", help="cpu or cuda:0")
    p.add_argument("--seed", type=int, default=0, help="seed")
    p.add_argument("--eval", action="store_true", help="replay every split with the identified model and report")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing while identifying (OUT/identify.log keeps every line; no progress bar)")


GAIN_GRID_HELP = ("factors on the robot file's kp to try before the gradient fit, each joint taking its own best, "
                  "e.g. 1,0.1,0.03,0.01 (for a file's servo far stiffer than the real one; default off)")


def parse_grid(text: str, flag: str, what: str) -> tuple[float, ...]:
    """A comma-separated grid of a command-line flag; a malformed one is a one-line :class:`UserError`."""
    from . import UserError

    try:
        return tuple(float(g) for g in text.split(",") if g.strip())
    except ValueError:
        raise UserError(f"{flag} {text!r}: give comma-separated {what}") from None


def run(args: argparse.Namespace) -> int:
    from dataclasses import replace
    from pathlib import Path

    from ..data.loading import load_data
    from ..learn.hybrid import save_identify_config
    from ..learn.sysid import SysIdConfig, identify
    from . import UserError

    kw = {k: v for k, v in (("iterations", args.iterations), ("windows", args.windows), ("solver", args.solver),
                            ("refine", args.refine)) if v is not None}
    if args.delay_grid is not None:
        kw["delay_grid"] = parse_grid(args.delay_grid, "--delay-grid", "numbers of steps")
    if args.gain_grid is not None:
        kw["gain_grid"] = parse_grid(args.gain_grid, "--gain-grid", "factors on kp")
    if args.fit is not None:
        kw["fit"] = tuple(f.strip() for f in args.fit.split(",") if f.strip())
    try:
        cfg = replace(SysIdConfig(), device=args.device, seed=args.seed, **kw)
    except ValueError as e:
        raise UserError(str(e)) from None
    ds, robot = load_data(args.data, args.robot, args.gains)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from ..progress import Log

    log = Log(out / "identify.log", quiet=args.quiet)
    log(f"identifying {', '.join(cfg.fit)} on {len(ds.split('train'))} trajectories of {args.data}: "
          f"{cfg.iterations} iterations x {cfg.windows} windows -> {out}")
    from ..sim.warmup import compile_kernels

    compile_kernels(robot, ds.rate_hz, ("forward", "param_grads"), solver=cfg.solver, device=cfg.device, say=log)
    try:
        params, curve = identify(robot, ds, cfg, out=out, log=log)
    except (ValueError, FloatingPointError) as e:
        raise UserError(str(e).splitlines()[0]) from None
    save_identify_config(out, cfg, ds.rate_hz, args.data)
    log(f"done: {curve[-1]['wall'] if curve else 0.0:.0f} s; wrote {out / 'physics.json'}")
    if args.eval:
        from ..evaluation.identification import write_identification_report
        from ..evaluation.evaluate_run import evaluate_run

        truth = None
        if ds.mismatch:
            from ..data.real_robot import Mismatch, RealRobot

            truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch), ds.rate_hz).physics()
        report = write_identification_report(out, params, truth, ds.split("train"))
        print(f"wrote {report}")
        evaluate_run(str(out), ds, robot, data_label=str(args.data))
    return 0
