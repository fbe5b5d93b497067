"""``wresdyn identify DATA``: identify the simulator's own physical parameters through the differentiable solver.

Grey-box system identification (:mod:`wresdyn.identify.sysid`): per joint PD gains, armature, viscous damping, dry
friction with stiction, effort limit and command delay; per link mass, centre of mass and inertia. The run
folder holds ``physics.json`` (the calibrated robot's parameters, JSON), ``config.json``, ``checkpoint.pt``
(resumed when present; a changed config is refused), ``curve.json`` and ``identify.log`` (every line printed;
``--quiet`` prints none); with ``--eval`` the calibrated model is replayed on every split (``eval/report.md``)
and, for data recorded on the simulated real robot, the identified values are compared with the truth
(``identification.md``, with the section of ``identifiability.md``: what the data can identify, also in
``identifiability.json`` unless ``--no-identifiability``). ``wresdyn fit DATA --physics RUN/physics.json``
then learns a residual on top (the hybrid model).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

import tyro

from ..identify.sysid_config import SysIdConfig
from .command import FLAT, Command


@dataclass(frozen=True)
class Identify(Command):
    """``wresdyn identify``: the dataset, the run folder and the identification's config (its fields as flags)."""

    data: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="DATA")]
    """Dataset file (.npz from `wresdyn collect`)."""
    out: str = "runs/identify"
    """Run folder."""
    robot: str | None = None
    """Robot file (default: the one the dataset was recorded on)."""
    gains: str | None = None
    """Gains config (TOML) by joint-name pattern; replaces the one stored in the dataset."""
    eval: bool = False
    """Replay every split with the identified model and report."""
    quiet: bool = False
    """Print nothing while identifying (OUT/identify.log keeps every line; no progress bar)."""
    config: Annotated[SysIdConfig, FLAT] = field(default_factory=SysIdConfig)
    """The identification."""


COMMAND = Identify


def run(args: Identify) -> int:
    from pathlib import Path

    from ..data.loading import load_data
    from ..fit.hybrid import save_identify_config
    from ..identify.sysid import identify
    from . import UserError

    cfg = args.config
    ds, robot = load_data(args.data, args.robot, args.gains)
    from ..sim.devices import require_device

    require_device(cfg.device)  # before OUT is made: a refused device leaves nothing behind
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from ..progress import Log

    log = Log(out / "identify.log", quiet=args.quiet)
    from ..learn.schedule import describe_length

    log(f"identifying {', '.join(cfg.fit)} on {len(ds.split('train'))} trajectories of {args.data}: "
        f"{describe_length(cfg)} x {cfg.windows} windows -> {out}")
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
            from ..data.mismatch import Mismatch
            from ..data.real_robot import RealRobot

            truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch), ds.rate_hz).physics()
        report = write_identification_report(out, params, truth, ds.split("train"))
        section = out / "identifiability.md"
        if section.exists():  # the run's identifiability (written by identify) as a section of the report
            with open(report, "a") as f:
                f.write("\n" + section.read_text())
        print(f"wrote {report}")
        evaluate_run(str(out), ds, robot, data_label=str(args.data))
    return 0
