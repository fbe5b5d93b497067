"""``wresdyn collect``: record a dataset on the simulated real robot, or import real logs into one.

Simulated: draws excitations (train / validation / held-out: the paper's ellipsoid foot paths, eq. 2;
out-of-distribution: chirps and kicks), executes them under PD on the MuJoCo "real" robot with the mismatch
config, and writes ``OUT/dataset.npz`` and ``OUT/spectrum.png`` (command spectrum per split). The foot paths
track ``--frames`` (default: the sites ``left_sole,right_sole``); ``--excitation joint`` (the default for a robot
without those sites, e.g. an arm) excites every joint in joint space instead (multisines; OOD: chirps and
steps). The gains config (``--gains``) is stored in the dataset, so later commands load the same robot. It
then replays the validation, held-out and OOD commands PD-only in Newton and reports the gap (mean |Δq|),
also stored in the dataset's meta.
Logs: ``--logs A.csv B.npz RUN_DIR LEROBOT_DIR ...`` imports real logs (CSV, NPZ, SAGE runs, LeRobot datasets;
docs/dataset.md) onto the ``--rate`` grid instead, with a ``--map`` file and splits by ``--assign`` / ``--split-map``
patterns or fractions, and reports the same PD-only gap.

Every line printed is also in ``OUT/collect.log``; on a terminal a progress bar over the trajectories shows the
elapsed and remaining time (:mod:`wresdyn.progress`), ``--quiet`` prints nothing.
"""

from __future__ import annotations

import argparse
from pathlib import Path

DEFAULT_MISMATCH = Path(__file__).resolve().parents[2] / "data" / "mismatch_default.toml"  # wresdyn.paths, no import


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", default=None, help="robot file (default: scenes/humanoid.usda)")
    p.add_argument("--gains", default=None, help="TOML file of PD gains by joint-name pattern")
    p.add_argument("--mismatch", default=str(DEFAULT_MISMATCH),
                   help="mismatch config (TOML) of the real robot, or 'none' for the nominal robot "
                        "(default: data/mismatch_default.toml)")
    p.add_argument("--train", type=int, default=16, help="number of training trajectories")
    p.add_argument("--validation", type=int, default=4,
                   help="number of validation trajectories (same family as train; for every tuning choice)")
    p.add_argument("--heldout", type=int, default=4, help="number of held-out trajectories (same family as train)")
    p.add_argument("--ood", type=int, default=4, help="number of out-of-distribution trajectories (chirp, kick)")
    p.add_argument("--duration", type=float, default=4.0, help="length of each trajectory [s]")
    p.add_argument("--rate", type=float, default=500.0, help="command and recording rate [Hz]")
    p.add_argument("--seed", type=int, default=0, help="master seed (same seed, same data)")
    p.add_argument("--out", default="data", help="output folder (default: data)")
    p.add_argument("--no-tau", action="store_true", help="do not store the measured (diagnostic) torque")
    p.add_argument("--no-gap", action="store_true", help="skip the PD-only Newton replay that measures the gap")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing while collecting (OUT/collect.log keeps every line; no progress bar)")
    p.add_argument("--excitation", default="auto", choices=("auto", "foot", "joint"),
                   help="foot: IK paths of --frames (the paper's); joint: joint-space multisines, chirps and steps "
                        "within limits, speed and effort; auto (default): foot when --frames is given or the robot "
                        "has left_sole and right_sole sites, joint otherwise")
    p.add_argument("--frames", default=None, metavar="A,B,...",
                   help="IK target frames (sites or bodies, comma-separated, any count) for the foot excitation "
                        "(default: left_sole,right_sole)")
    p.add_argument("--max-velocity", type=float, default=None, metavar="RAD_S",
                   help="command speed bound [rad/s] (default: 12 for foot paths, 5 in joint space)")
    p.add_argument("--logs", nargs="+", default=None, metavar="LOG",
                   help="import these real logs instead of simulating: .csv/.npz files, SAGE run folders, LeRobot "
                        "dataset folders (one trajectory per episode) or folders of runs (docs/dataset.md)")
    from ..data.dataset import SPLITS  # numpy only: cheap

    p.add_argument("--map", default=None, metavar="TOML",
                   help="logs: mapping file (log joint -> robot joint, units, excluded joints)")
    p.add_argument("--split", default=None, choices=SPLITS,
                   help="logs: split of every run no --assign/--split-map pattern or fraction assigns (default: "
                        "heldout; train when any of those is given)")
    p.add_argument("--assign", action="append", default=[], metavar="PATTERN=SPLIT",
                   help="logs: runs whose name matches the fnmatch PATTERN go to SPLIT (repeatable; first match wins)")
    p.add_argument("--split-map", default=None, metavar="TOML",
                   help="logs: file of '\"PATTERN\" = \"SPLIT\"' lines, tried after --assign")
    p.add_argument("--validation-fraction", type=float, default=0.0, metavar="F",
                   help="logs: this fraction of the unassigned runs goes to validation (whole runs, deterministic)")
    p.add_argument("--heldout-fraction", type=float, default=0.0, metavar="F",
                   help="logs: this fraction of the unassigned runs goes to heldout (whole runs, deterministic)")


def _import_logs(args: argparse.Namespace, robot, out: Path, path: Path, log) -> int:
    """``--logs``: read every run, assign splits, report the sampling of each log and the PD-only gap, and only
    then write the dataset (an error anywhere leaves nothing behind)."""
    from ..data.importers import SplitRule, import_runs, load_split_map, parse_assign
    from ..data.logs import LogMap

    if not args.no_gap:
        robot.check_gains()  # only the PD-only replay needs gains: --no-gap imports onto a robot without them
    log_map = LogMap.load(args.map) if args.map else None
    patterns = [parse_assign(a) for a in args.assign] + (load_split_map(args.split_map) if args.split_map else [])
    ruled = bool(patterns) or args.validation_fraction > 0 or args.heldout_fraction > 0
    rule = SplitRule(args.split or ("train" if ruled else "heldout"), tuple(patterns), args.validation_fraction,
                     args.heldout_fraction)
    ds = import_runs(args.logs, robot, args.rate, log_map, rule, store_tau=not args.no_tau)
    for p in rule.unused([tr.name for tr in ds.trajectories]):
        log(f"note: split pattern {p!r} matches no run")
    log(f"imported {len(ds.trajectories)} run(s) onto {args.rate:g} Hz:")
    for s in ds.meta["source_logs"]:
        log(f"  {s['name']:28s} {s['split']:10s} {s['format']:7s} {s['samples']:6d} samples {s['duration_s']:8.2f} s  "
             f"median {s['median_rate_hz']:8.3f} Hz  jitter {100 * s['jitter']:.3f} %  max gap "
             f"{1e3 * s['max_gap_s']:.2f} ms")
    excluded = ds.meta["excluded_joints"]
    if excluded:
        log(f"excluded from fitting (recorded values kept): {', '.join(excluded)}")
    if not args.no_gap:
        ds.meta["pd_only_gap"] = _pd_gaps(ds, robot, args.rate, "run(s)", log)
    out.mkdir(parents=True, exist_ok=True)
    ds.save(path)
    counts = ", ".join(f"{len(ds.split(s))} {s}" for s in ("train", "validation", "heldout", "ood") if ds.split(s))
    log(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB): {counts}")
    return 0


def run(args: argparse.Namespace) -> int:
    from ..data.dataset import SPLITS
    from ..robot.description import DEFAULT_ROBOT, load_robot
    from . import UserError

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"{out}: --out must be a folder")
    if not args.rate > 0:
        raise UserError(f"--rate must be > 0, not {args.rate}")
    robot = load_robot(args.robot or DEFAULT_ROBOT, gains=args.gains)
    path = out / "dataset.npz"
    from ..progress import Log

    log = Log(out / "collect.log", quiet=args.quiet)
    if args.logs:
        return _import_logs(args, robot, out, path, log)

    robot.check_replay()  # simulating needs PD gains and stated effort limits
    import dataclasses

    from ..data.excitation import ExcitationConfig, plot_spectrum
    from ..data.real_robot import Mismatch, collect

    counts = {"train": args.train, "validation": args.validation, "heldout": args.heldout, "ood": args.ood}
    if any(n < 0 for n in counts.values()) or sum(counts.values()) == 0:
        raise UserError("--train/--validation/--heldout/--ood must be >= 0 and not all 0")
    if not args.duration * args.rate >= 2:
        raise UserError(f"--duration {args.duration} s at {args.rate:g} Hz gives fewer than 2 samples")
    mismatch = Mismatch() if args.mismatch.lower() == "none" else Mismatch.load(args.mismatch)
    cfg = ExcitationConfig(mode="foot" if args.frames and args.excitation == "auto" else args.excitation)
    if args.frames is not None:
        if args.excitation == "joint":
            raise UserError("--frames sets the IK targets of the foot excitation; it has no use with "
                            "--excitation joint")
        frames = tuple(f.strip() for f in args.frames.split(",") if f.strip())
        if not frames:
            raise UserError(f"--frames {args.frames!r} names no frame")
        cfg = dataclasses.replace(cfg, frames=frames)
    if args.max_velocity is not None:
        if not args.max_velocity > 0:
            raise UserError(f"--max-velocity must be > 0, not {args.max_velocity}")
        cfg = dataclasses.replace(cfg, max_velocity=args.max_velocity, joint_max_velocity=args.max_velocity)
    log(f"collecting {sum(counts.values())} trajectories of {args.duration:g} s at {args.rate:g} Hz on "
         f"{robot.source.name} with mismatch {'none (nominal)' if mismatch.is_nominal() else args.mismatch}, "
         f"seed {args.seed}")
    ds = collect(robot, mismatch, counts, args.duration, args.rate, args.seed, cfg, store_tau=not args.no_tau,
                 progress=log)
    if not args.no_gap:
        ds.meta["pd_only_gap"] = _pd_gaps(ds, robot, args.rate, "trajectories", log)
    out.mkdir(parents=True, exist_ok=True)
    ds.save(path)
    plot_spectrum({s: [tr.q_cmd for tr in ds.split(s)] for s in SPLITS}, args.rate, out / "spectrum.png",
                  ds.joint_names)
    log(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB) and {out / 'spectrum.png'}")
    return 0


def _pd_gaps(ds, robot, rate: float, what: str, log) -> dict:
    """The PD-only gap of every evaluation split of ``ds`` (:func:`~wresdyn.evaluation.open_loop.pd_gap`, over the
    fitted joints), announced line by line; ``what`` names the trajectories in the lines ("run(s)", ...)."""
    from ..evaluation.open_loop import pd_gap
    from ..sim.warmup import compile_kernels

    excluded = ds.excluded_joints
    if any(ds.split(s) for s in ("validation", "heldout", "ood")):
        compile_kernels(robot, rate, ("forward",), say=log)
    gaps = {}
    for split in ("validation", "heldout", "ood"):
        trajs = ds.split(split)
        if trajs:
            log(f"replaying {len(trajs)} {split} {what} PD-only in Newton (nominal robot)")
            g = gaps[split] = pd_gap(robot, trajs, rate, weights=ds.fit_weights())
            line = f"  PD-only vs real on {split}: mean |dq| {g['mean']:.4f} +- {g['std']:.4f} rad"
            if excluded:
                line += (f" over the {len(ds.fitted_joints)} fitted joints (excluded: "
                         + ", ".join(f"{j} {g['per_joint'][j]:.4f} rad" for j in excluded) + ")")
            log(line + (f"; {g['diverged']} replay(s) diverged" if g["diverged"] else ""))
    return gaps
