"""``wresdyn collect``: record a dataset on the simulated real robot, or import real logs into one.

Simulated: draws excitations (train / validation / held-out: the paper's ellipsoid foot paths, eq. 2;
out-of-distribution: chirps and kicks), executes them under PD on the MuJoCo "real" robot with the mismatch
config, and writes ``OUT/dataset.npz`` and ``OUT/spectrum.png`` (command spectrum per split). The foot paths
track ``--excitation.frames`` (default: the sites ``left_sole right_sole``); ``--excitation.mode joint`` (the
default for a robot without those sites, e.g. an arm) excites every joint in joint space instead (multisines; OOD:
chirps and steps). The gains config (``--gains``) is stored in the dataset, so later commands load the same robot. It
then replays the validation, held-out and OOD commands PD-only in Newton and reports the gap (mean |Δq|),
also stored in the dataset's meta.
Logs: ``--logs A.csv B.npz C.mcap RUN_DIR LEROBOT_DIR ...`` imports real logs (CSV, NPZ, MCAP / ROS 2 bags with
``--topic-*`` options, SAGE runs, LeRobot datasets; docs/dataset.md) onto the ``--rate`` grid instead, with a
``--map`` file and splits by ``--assign`` / ``--split-map`` patterns or fractions, prints the telemetry checks'
warnings (:mod:`wresdyn.data.telemetry`; also in ``OUT/telemetry.json``) and reports the same PD-only gap.

Every line printed is also in ``OUT/collect.log``; on a terminal a progress bar over the trajectories shows the
elapsed and remaining time (:mod:`wresdyn.progress`), ``--quiet`` prints nothing.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Literal

import tyro

from ..choices import check_number
from ..data.dataset import SPLITS  # numpy only: cheap
from ..data.probe import SaturationProbe
from ..data.signals import SOLES, ExcitationConfig
from ..errors import WresdynError
from .command import FLAT, Command

Split = Literal["train", "validation", "heldout", "ood"]  # data.dataset.SPLITS

DEFAULT_MISMATCH = Path(__file__).resolve().parents[2] / "data" / "mismatch_default.toml"  # wresdyn.paths, no import


@dataclass(frozen=True)
class CollectConfig:
    """What ``wresdyn collect`` records on the simulated real robot (:func:`wresdyn.data.real_robot.collect`)."""

    train: int = 16
    """Training trajectories."""
    validation: int = 4
    """Validation trajectories (same family as train; for every tuning choice)."""
    heldout: int = 4
    """Held-out trajectories (same family as train)."""
    ood: int = 4
    """Out-of-distribution trajectories (chirp, kick; joint space: chirp, steps)."""
    duration: float = 4.0
    """Length of each trajectory [s]."""
    rate: float = 500.0
    """Command and recording rate [Hz] (logs: the grid they are resampled onto)."""
    seed: int = 0
    """Master seed (same seed, same data)."""
    excitation: ExcitationConfig = field(default_factory=ExcitationConfig)
    """The excitation's mode, frames and parameter ranges."""
    probe_saturation: int = 0
    """Saturation probe trajectories added to the training split (foot mode: each leg joint in turn steps far
    enough that its drive saturates, so identification sees its effort limit; :mod:`wresdyn.data.probe`)."""
    probe: SaturationProbe = field(default_factory=SaturationProbe)
    """The saturation probe's step sizes and timing."""

    def __post_init__(self) -> None:
        check_number(self.rate, "rate", gt=0)
        counts = [self.train, self.validation, self.heldout, self.ood]
        for name, n in zip(SPLITS, counts):
            check_number(n, name, integer=True, ge=0)
        check_number(self.probe_saturation, "probe_saturation", integer=True, ge=0)
        if not any(counts) and not self.probe_saturation:
            raise WresdynError("train/validation/heldout/ood are all 0: nothing to record")
        check_number(self.duration, "duration", gt=0)
        if not self.duration * self.rate >= 2:
            raise WresdynError(f"duration {self.duration} s at {self.rate:g} Hz gives fewer than 2 samples")

    @property
    def counts(self) -> dict[str, int]:
        """Trajectories per split."""
        return {"train": self.train, "validation": self.validation, "heldout": self.heldout, "ood": self.ood}


@dataclass(frozen=True)
class Collect(Command):
    """``wresdyn collect``: the robot, the real robot's mismatch, where the dataset goes, what is recorded
    (:class:`CollectConfig`, its fields as flags; ``--excitation.mode auto`` is foot when ``--excitation.frames``
    is given or the robot has left_sole and right_sole sites, joint otherwise), or the real logs imported
    instead."""

    robot: str | None = None
    """Robot file (default: scenes/humanoid.usda)."""
    gains: str | None = None
    """TOML file of PD gains by joint-name pattern."""
    mismatch: str = str(DEFAULT_MISMATCH)
    """Mismatch config (TOML) of the real robot, or 'none' for the nominal robot (default:
    data/mismatch_default.toml)."""
    out: str = "data"
    """Output folder."""
    tau: bool = True
    """Store the measured (diagnostic) torque."""
    gap: bool = True
    """Replay the evaluation splits PD-only in Newton and report the gap."""
    quiet: bool = False
    """Print nothing while collecting (OUT/collect.log keeps every line; no progress bar)."""
    max_velocity: Annotated[float | None, tyro.conf.arg(metavar="RAD_S")] = None
    """Command speed bound [rad/s] of both modes: --excitation.max-velocity and --excitation.joint-max-velocity at
    once."""
    recording: Annotated[CollectConfig, FLAT] = field(default_factory=CollectConfig)
    """What is recorded."""
    logs: Annotated[tuple[str, ...] | None, tyro.conf.arg(metavar="LOG")] = None
    """Import these real logs instead of simulating: .csv/.npz/.mcap files, SAGE run folders, LeRobot dataset folders
    (one trajectory per episode) or folders of runs (docs/dataset.md)."""
    map: Annotated[str | None, tyro.conf.arg(metavar="TOML")] = None
    """Logs: mapping file (log joint -> robot joint, units, excluded joints)."""
    lerobot_units: Literal["degrees", "range"] | None = None
    """Logs: LeRobot datasets of an SO-100/SO-101 follower read without --map: the arm joints were recorded in
    degrees (--robot.use_degrees=true) or in -100..100 range units (false) (None: the robot type's LeRobot default:
    so_follower degrees, so100_follower and so101_follower range)."""
    lerobot_calibration: Annotated[str | None, tyro.conf.arg(metavar="JSON")] = None
    """Logs: the follower's calibration file (~/.cache/huggingface/lerobot/calibration/robots/<robot_type>/<id>.json):
    converts range units to radians."""
    topic_state: str = "/joint_states"
    """Logs: MCAP topic of the measured state (sensor_msgs/msg/JointState: position, velocity and effort)."""
    topic_command: str | None = None
    """Logs: MCAP topic of the commands (JointState, trajectory_msgs/msg/JointTrajectory or
    std_msgs/msg/Float64MultiArray; None: the one other topic of those types in the file)."""
    topic_command_joints: Annotated[tuple[str, ...], tyro.conf.arg(metavar="JOINT")] = ()
    """Logs: the joint of each entry of Float64MultiArray commands, in order (the controller's 'joints' parameter;
    empty: the state topic's joint order)."""
    topic_stamps: Literal["auto", "header", "log"] = "auto"
    """Logs: MCAP time stamps: header stamps where every message of a topic has one, else the recorder's log time
    (auto), header stamps only, or log time only."""
    split: Split | None = None
    """Logs: split of every run no --assign/--split-map pattern or fraction assigns (None: heldout; train when any
    of those is given)."""
    assign: Annotated[tuple[str, ...], tyro.conf.UseAppendAction, tyro.conf.arg(metavar="PATTERN=SPLIT")] = ()
    """Logs: runs whose name matches the fnmatch PATTERN go to SPLIT (repeatable; first match wins)."""
    split_map: Annotated[str | None, tyro.conf.arg(metavar="TOML")] = None
    """Logs: file of '"PATTERN" = "SPLIT"' lines, tried after --assign."""
    validation_fraction: float = 0.0
    """Logs: this fraction of the unassigned runs goes to validation (whole runs, deterministic)."""
    heldout_fraction: float = 0.0
    """Logs: this fraction of the unassigned runs goes to heldout (whole runs, deterministic)."""

    def __post_init__(self) -> None:
        ex = self.recording.excitation
        if ex.frames != SOLES:
            if ex.mode == "joint":
                raise WresdynError("--excitation.frames sets the IK targets of the foot excitation; it has no use "
                                   "with --excitation.mode joint")
            if not ex.frames:
                raise WresdynError("--excitation.frames names no frame")
        if self.max_velocity is not None and not self.max_velocity > 0:
            raise WresdynError(f"--max-velocity must be > 0, not {self.max_velocity}")

    @property
    def config(self) -> CollectConfig:
        """What is recorded: frames of their own without a mode select the foot mode, ``--max-velocity`` bounds
        both modes."""
        ex = self.recording.excitation
        given = {}
        if ex.frames != SOLES and ex.mode == "auto":
            given["mode"] = "foot"
        if self.max_velocity is not None:
            given["max_velocity"] = given["joint_max_velocity"] = self.max_velocity
        return replace(self.recording, excitation=replace(ex, **given)) if given else self.recording


COMMAND = Collect


def _import_logs(args: Collect, rate: float, robot, out: Path, path: Path, log) -> int:
    """``--logs``: read every run, assign splits, report the sampling of each log and the PD-only gap, and only
    then write the dataset (an error anywhere leaves nothing behind)."""
    from ..data.importers import SplitRule, import_runs, load_split_map, parse_assign
    from ..data.lerobot import LeRobotUnits
    from ..data.logs import LogMap
    from ..data.mcap_logs import McapTopics

    if args.gap:
        robot.check_gains()  # only the PD-only replay needs gains: --no-gap imports onto a robot without them
    log_map = LogMap.load(args.map) if args.map else None
    patterns = [parse_assign(a) for a in args.assign] + (load_split_map(args.split_map) if args.split_map else [])
    ruled = bool(patterns) or args.validation_fraction > 0 or args.heldout_fraction > 0
    rule = SplitRule(args.split or ("train" if ruled else "heldout"), tuple(patterns), args.validation_fraction,
                     args.heldout_fraction)
    lerobot = (LeRobotUnits.load(args.lerobot_calibration, args.lerobot_units)
               if args.lerobot_calibration or args.lerobot_units else None)
    topics = McapTopics(args.topic_state, args.topic_command, args.topic_command_joints, args.topic_stamps)
    ds = import_runs(args.logs, robot, rate, log_map, rule, store_tau=args.tau, lerobot=lerobot, topics=topics)
    for p in rule.unused([tr.name for tr in ds.trajectories]):
        log(f"note: split pattern {p!r} matches no run")
    log(f"imported {len(ds.trajectories)} run(s) onto {rate:g} Hz:")
    for s in ds.meta["source_logs"]:
        log(f"  {s['name']:28s} {s['split']:10s} {s['format']:7s} {s['samples']:6d} samples {s['duration_s']:8.2f} s  "
             f"median {s['median_rate_hz']:8.3f} Hz  jitter {100 * s['jitter']:.3f} %  max gap "
             f"{1e3 * s['max_gap_s']:.2f} ms")
    for file, u in {s["file"]: s["units"] for s in ds.meta["source_logs"] if "units" in s}.items():
        calibration = f" (calibration {u['calibration']})" if u["calibration"] else ""
        log(f"{file}: LeRobot {u['robot_type']}, no map: joints by motor name, arm in {u['arm_units']} units"
            f"{calibration} -> rad about the robot file's zero, gripper 0..100 -> its joint range")
    for s in ds.meta["source_logs"]:
        if s["format"] == "mcap":
            st, cm = s["topics"]["state"], s["topics"]["command"]
            log(f"{s['file']}: state {st['topic']} ({st['messages']} messages, {st['stamps']} stamps), command "
                f"{cm['topic']} ({cm['type']}, {cm['messages']} messages, {cm['stamps']} stamps)")
    excluded = ds.meta["excluded_joints"]
    if excluded:
        log(f"excluded from fitting (recorded values kept): {', '.join(excluded)}")
    findings = ds.meta["telemetry"]
    log(f"telemetry checks (docs/logs.md): {len(findings)} warning(s)" + (":" if findings else ""))
    for f in findings:
        log(f"warning: {f['message']}")
    if args.gap:
        ds.meta["pd_only_gap"] = _pd_gaps(ds, robot, rate, "run(s)", log)
    out.mkdir(parents=True, exist_ok=True)
    ds.save(path)
    report = out / "telemetry.json"  # one record per finding, also in the dataset's meta["telemetry"]
    report.write_text(json.dumps(findings, indent=1) + "\n")
    counts = ", ".join(f"{len(ds.split(s))} {s}" for s in ("train", "validation", "heldout", "ood") if ds.split(s))
    log(f"wrote {path} ({path.stat().st_size / 1e6:.2f} MB) and {report}: {counts}")
    return 0


def run(args: Collect) -> int:
    from ..robot.description import DEFAULT_ROBOT, load_robot
    from . import UserError

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise UserError(f"{out}: --out must be a folder")
    cfg = args.config
    robot = load_robot(args.robot or DEFAULT_ROBOT, gains=args.gains)
    path = out / "dataset.npz"
    from ..progress import Log

    log = Log(out / "collect.log", quiet=args.quiet)
    if args.logs:
        return _import_logs(args, cfg.rate, robot, out, path, log)

    robot.check_replay()  # simulating needs PD gains and stated effort limits
    from ..data.spectrum import plot_spectrum
    from ..data.mismatch import Mismatch
    from ..data.real_robot import RealRobot, collect
    from ..sim.first_steps import check_mujoco

    mismatch = Mismatch() if args.mismatch.lower() == "none" else Mismatch.load(args.mismatch)
    check_mujoco(RealRobot(robot, mismatch, cfg.rate))  # a model that blows up is refused before the long recording
    probes = f" (with {cfg.probe_saturation} saturation probes)" if cfg.probe_saturation else ""
    log(f"collecting {sum(cfg.counts.values()) + cfg.probe_saturation} trajectories{probes} of {cfg.duration:g} s at "
        f"{cfg.rate:g} Hz on {robot.source.name} with mismatch "
        f"{'none (nominal)' if mismatch.is_nominal() else args.mismatch}, seed {cfg.seed}")
    ds = collect(robot, mismatch, cfg.counts, cfg.duration, cfg.rate, cfg.seed, cfg.excitation,
                 store_tau=args.tau, progress=log, probe=cfg.probe_saturation, probe_config=cfg.probe)
    if args.gap:
        ds.meta["pd_only_gap"] = _pd_gaps(ds, robot, cfg.rate, "trajectories", log)
    out.mkdir(parents=True, exist_ok=True)
    ds.save(path)
    plot_spectrum({s: [tr.q_cmd for tr in ds.split(s)] for s in SPLITS}, cfg.rate, out / "spectrum.png",
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
