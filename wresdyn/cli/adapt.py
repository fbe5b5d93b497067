"""``wresdyn adapt RUN LOG``: keep a run's identified physics up to date from a stream of the robot's samples.

RUN is a folder holding ``physics.json`` (``wresdyn identify``, a hybrid ``wresdyn fit``): the warm start. LOG is a
dataset (``.npz``: its trajectories replayed one after the other as a stream, :mod:`wresdyn.adapt.stream`), a text
file, or ``-`` for a live stream on stdin, one sample per line: ``t q1..qn qd1..qdn qcmd1..qcmdn``. Every
``--update-every`` seconds of robot time the online identifier (:class:`~wresdyn.adapt.adapter.Adapter`) fits on
its sliding window and keeps the update only if it lowers the open-loop error on the latest held-back seconds; each
update prints a line (robot time, accepted or not, the held-back open-loop and one-step errors of the adapted model
and of the run's physics held fixed, the compute, the tracked parameters). OUT gets ``physics/`` (each accepted
update, ``physics.json``-compatible with its time ``t`` [s], and ``physics.json``, the latest), ``updates.csv`` and
``updates.json`` (every update, every adapted parameter), ``adapt.png`` and ``adapt.log``. ``--export DIR`` keeps
the calibrated robot exported there (:func:`wresdyn.export.usd.write_export`), rewritten with each update.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Annotated

import tyro

from ..adapt.config import AdaptConfig
from .command import FLAT, Command


@dataclass(frozen=True)
class Adapt(Command):
    """``wresdyn adapt``: the warm start, the stream, where the updates go and the online identification's config
    (its fields as flags)."""

    run: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="RUN")]
    """Run folder with physics.json (the warm start)."""
    log: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="LOG")]
    """Dataset (.npz), text file of samples, or - for stdin; a text line is one sample: t q1..qn qd1..qdn
    qcmd1..qcmdn (SI units, time increasing)."""
    out: str = "runs/adapt"
    """Output folder."""
    robot: str | None = None
    """Robot file (default: a dataset's own; for text, the one of the run's config.json data_path)."""
    rate_hz: float | None = None
    """Sample rate of a text stream [Hz] (default: the run's config.json rate_hz, else 500)."""
    split: tuple[str, ...] = ()
    """A dataset's splits to stream (default: all, in the file's order)."""
    track: tuple[str, ...] = ()
    """Parameters to print, FIELD:NAME (fnmatch on joint/body names, e.g. friction:*knee body_mass:torso); default:
    the three that moved most."""
    export: str | None = None
    """Keep the calibrated robot exported in this folder as `wresdyn export --physics-only` writes it (robot.usda,
    actuated.usda, physics.json): the warm start first, rewritten atomically with each published update (a USD
    robot only)."""
    quiet: bool = False
    """Print nothing per update (OUT/adapt.log keeps every line)."""
    config: Annotated[AdaptConfig, FLAT] = field(default_factory=AdaptConfig)
    """The online identification."""


COMMAND = Adapt


def _source(args):
    """``(robot, rate_hz, blocks)`` of the LOG argument."""
    import json
    import sys
    from pathlib import Path

    from ..adapt.stream import dataset_blocks, text_blocks
    from ..data.loading import dataset_robot, load_data
    from . import UserError

    if args.log.endswith(".npz"):
        ds, robot = load_data(args.log, args.robot)
        if args.split and not any(tr.split in args.split for tr in ds.trajectories):
            raise UserError(f"{args.log}: no trajectory in split(s) {', '.join(args.split)}")
        return robot, ds.rate_hz, dataset_blocks(ds, args.split)
    config = Path(args.run, "config.json")
    record = json.loads(config.read_text()) if config.is_file() else {}
    robot_file = args.robot
    if robot_file is None:
        data = record.get("data_path")
        if not data or data == "None" or not Path(data).is_file():
            raise UserError(f"{args.run}: config.json names no dataset to take the robot from; pass --robot")
        _, robot = load_data(data)
    else:
        robot = dataset_robot(robot_file)
    rate = args.rate_hz or float(record.get("rate_hz", 500.0))
    if args.log == "-":
        return robot, rate, text_blocks(sys.stdin, robot.n_dof)
    if not Path(args.log).is_file():
        raise UserError(f"{args.log}: no such file")
    return robot, rate, text_blocks(open(args.log), robot.n_dof, where=args.log, block=500)


def run(args: Adapt) -> int:
    import dataclasses
    from pathlib import Path

    from ..errors import WresdynError
    from ..learn.runs import run_physics
    from . import UserError

    cfg = args.config
    if not Path(args.run).is_dir():
        raise UserError(f"{args.run}: no such run folder")
    if not Path(args.run, "physics.json").is_file():
        raise UserError(f"{args.run}: no physics.json (a wresdyn identify or hybrid fit run folder)")
    robot, rate, blocks = _source(args)
    start = run_physics(args.run, robot)
    if args.export is not None:
        from ..export.usd import check_usd_robot

        check_usd_robot(robot)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    from ..progress import Log

    log = Log(out / "adapt.log", quiet=args.quiet)
    from ..adapt.adapter import Adapter
    from ..adapt.timeline import parameter_columns, plot_updates, tracked_names, write_updates

    adapter = Adapter(robot, start, rate, cfg, publish=out / "physics", export=args.export)
    names = tracked_names(start, cfg.fit, args.track)
    log(f"adapting {', '.join(cfg.fit)} of {args.run} on {args.log} at {rate:g} Hz: window {cfg.window:g} s, "
        f"held back {cfg.holdout:g} s, {cfg.iterations} Adam steps x {cfg.windows} windows x {cfg.horizon} every "
        f"{cfg.update_every:g} s -> {out}")
    streamed = 0.0
    try:
        for t, q, qd, q_cmd in blocks:
            for u in adapter.push(t, q, qd, q_cmd):
                cols = parameter_columns(u.physics, cfg.fit)
                shown = names if args.track else tracked_names(start, cfg.fit, latest=u.physics)
                verdict = "accepted" if u.accepted else "reverted" if u.reverted else "rejected"
                log(f"t {u.t:8.2f} s  {verdict}  open-loop {u.open_loop:.5f} rad "
                    f"(fixed {u.open_loop_start:.5f})  one-step {u.one_step:.6f} (fixed {u.one_step_start:.6f})  "
                    f"compute {u.compute:.2f} s  " + "  ".join(f"{n} {cols[n]:.4g}" for n in shown)
                    + (f"  tracking (jump {u.jump:.2f})" if u.tracking else "")
                    + (f"  effort grid: {u.effort_set}" if u.effort_set else ""))
            streamed += len(t) / rate
    except WresdynError as e:
        raise UserError(str(e).splitlines()[0]) from None
    ups = adapter.updates
    if not ups:
        raise UserError(f"{args.log}: too short for an update ({streamed:.2f} s of samples; an update needs "
                        f"{cfg.holdout:g} s held back after a window of {cfg.horizon} steps)")
    rtf = streamed / adapter.compute if adapter.compute > 0 else float("inf")
    summary = {"run": str(args.run), "log": str(args.log), "rate_hz": rate, "config": dataclasses.asdict(cfg),
               "robot_time_s": streamed, "compute_s": adapter.compute, "real_time_factor": rtf,
               "n_updates": len(ups), "accepted": sum(u.accepted for u in ups),
               "reverted": sum(u.reverted for u in ups)}
    csv_path, _ = write_updates(out, ups, cfg.fit, summary)
    plot = plot_updates(out / "adapt.png", ups, start, names if args.track else
                        tracked_names(start, cfg.fit, latest=ups[-1].physics))
    log(f"done: {len(ups)} updates, {summary['accepted']} accepted, {summary['reverted']} back to the warm start; "
        f"{streamed:.1f} s of robot time in {adapter.compute:.1f} s of updates (real-time factor {rtf:.2f}); wrote {csv_path}, {plot}, "
        f"{out / 'physics'}" + (f", {args.export}" if args.export else ""))
    return 0
