"""LeRobot's own metadata and units: a dataset recorded with a LeRobot follower arm imports without a mapping file.

LeRobot's SO-100 / SO-101 follower (``robot_type`` ``so100_follower`` / ``so101_follower`` in ``meta/info.json``,
``so_follower`` from LeRobot 0.4 on; six Feetech STS3215 servos, 4096 encoder ticks per turn) records
``observation.state`` (present position) and ``action`` (goal position) with one entry per motor, named
``<motor>.pos`` in the features' ``names``. The motor names are the SO-101 robot file's joint names. Values are in
the normalised units of LeRobot's motor bus (``MotorNormMode``), from the follower's calibration (``range_min``,
``range_max`` [ticks], ``drive_mode``):

* arm joints with ``--robot.use_degrees=true`` (the default of ``so_follower``): DEGREES,
  deg = (ticks − mid)·360/4095 with mid = (range_min + range_max)/2;
* arm joints with ``use_degrees=false`` (the default of ``so100_follower`` / ``so101_follower``): RANGE_M100_100,
  v = 200·(ticks − range_min)/(range_max − range_min) − 100, negated with drive_mode 1;
* the gripper: RANGE_0_100, v = 100·(ticks − range_min)/(range_max − range_min).

The robot file's zero is the middle of each calibrated range (SO-ARM100's "new_calib" convention, also LeRobot's own
MuJoCo model's), so with 2π/4096 rad per tick

* degrees: q = deg · (4095/4096) · π/180 [rad] (no calibration needed),
* range units: q = ±v/100 · (range_max − range_min)/2 · 2π/4096 [rad] (the calibration file is needed),

and the gripper's 0..100 opening maps linearly onto the robot's joint range and is excluded from fitting, as
``data/so101/map.toml`` does for the SAGE logs of the same arm. :func:`derive_map` turns this into a
:class:`~wresdyn.data.log_files.LogMap`; :func:`load_calibration` reads LeRobot's calibration file
(``~/.cache/huggingface/lerobot/calibration/robots/<robot_type>/<id>.json``).
"""

from __future__ import annotations

import itertools
import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .dataset import DatasetError
from .log_files import IDENTITY, LogMap, Run, check_finite, check_stamps, map_joints

__all__ = ["FOLLOWERS", "UNITS", "Follower", "MotorRange", "LeRobotUnits", "load_calibration", "derive_map",
           "check_range_units", "lerobot_root", "read_lerobot", "read_lerobot_runs"]

TICKS_PER_TURN = 4096
"""Encoder ticks per turn of the STS3215 (LeRobot's ``model_resolution_table``)."""
LEROBOT_SUFFIXES = (".pos", ".vel", ".effort")
"""LeRobot names motor features ``<motor>.pos`` (``.vel``, ``.effort``); the suffix is dropped to get the joint."""
RANGE_SLACK = 1e-3
"""LeRobot clamps a present position into its calibrated range before normalising: a range-unit
``observation.state`` lies in [-100, 100] up to float32 rounding, which this margin allows."""


@dataclass(frozen=True)
class Follower:
    """A LeRobot follower arm whose units are known."""

    motors: tuple[str, ...]
    """Motor names in LeRobot's order (the ``<motor>`` of its ``<motor>.pos`` features)."""
    gripper: str
    """The motor in RANGE_0_100 units (the others: DEGREES or RANGE_M100_100)."""
    default_units: str
    """Units of the arm joints unless the recording said otherwise: ``"degrees"`` or ``"range"`` (the default of
    ``use_degrees`` in that robot type's LeRobot versions)."""


_SO_MOTORS = ("shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper")
FOLLOWERS = {"so100_follower": Follower(_SO_MOTORS, "gripper", "range"),
             "so101_follower": Follower(_SO_MOTORS, "gripper", "range"),
             "so_follower": Follower(_SO_MOTORS, "gripper", "degrees")}
"""``robot_type`` of ``meta/info.json`` -> follower: ``so100_follower`` / ``so101_follower`` (LeRobot up to 0.3,
``use_degrees`` false by default), ``so_follower`` (both arms from LeRobot 0.4 on, ``use_degrees`` true by default)."""
UNITS = ("degrees", "range")
"""How the arm joints of a follower were recorded: LeRobot's DEGREES or RANGE_M100_100."""


@dataclass(frozen=True)
class MotorRange:
    """One motor of a LeRobot calibration file."""

    range_min: int
    """Lower end of the calibrated range [ticks]."""
    range_max: int
    """Upper end of the calibrated range [ticks]."""
    drive_mode: int = 0
    """1: LeRobot negates the range units of this motor."""


@dataclass(frozen=True)
class LeRobotUnits:
    """What converts a LeRobot dataset's normalised units to radians where its ``meta/info.json`` does not say."""

    calibration: dict[str, MotorRange] | None = None
    """The follower's calibration by motor name (``None``: not given)."""
    calibration_file: str = ""
    """File the calibration was read from, for messages and the dataset's meta."""
    arm: str | None = None
    """Units of the arm joints, one of :data:`UNITS` (``use_degrees`` true: ``"degrees"``); ``None``: the robot
    type's default (:attr:`Follower.default_units`)."""
    ranges: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Robot joint name -> (lower, upper) limit [rad]: where a RANGE_0_100 motor's 0 and 100 lie."""

    @classmethod
    def load(cls, calibration: str | Path | None = None, arm: str | None = None) -> LeRobotUnits:
        """Units from a calibration file (optional) and the arm's units (``None``: the robot type's default)."""
        if arm is not None and arm not in UNITS:
            raise DatasetError(f"LeRobot arm units {arm!r}: choose from {', '.join(UNITS)}")
        if calibration is None:
            return cls(arm=arm)
        return cls(load_calibration(calibration), str(calibration), arm)


def load_calibration(path) -> dict[str, MotorRange]:
    """A LeRobot calibration file (JSON: ``{motor: {"id", "drive_mode", "homing_offset", "range_min",
    "range_max"}}``) as ``{motor: MotorRange}``; anything else is a one-line :class:`DatasetError`."""
    path = Path(path)
    try:
        raw = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise DatasetError(f"{path}: LeRobot calibration file not found") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{path}: not a readable JSON calibration file: {e}") from None
    if not isinstance(raw, dict) or not raw:
        raise DatasetError(f"{path}: a LeRobot calibration file maps motor names to their calibration")
    out = {}
    for motor, c in raw.items():
        ok = isinstance(c, dict) and all(isinstance(c.get(k), int) and not isinstance(c.get(k), bool)
                                         for k in ("range_min", "range_max"))
        if not ok:
            raise DatasetError(f"{path}: motor {motor!r} needs integer range_min and range_max [ticks], got {c!r}")
        lo, hi, mode = c["range_min"], c["range_max"], c.get("drive_mode", 0)
        if not 0 <= lo < hi < TICKS_PER_TURN:
            raise DatasetError(f"{path}: motor {motor!r}: range_min {lo} and range_max {hi} must satisfy "
                               f"0 <= range_min < range_max < {TICKS_PER_TURN}")
        if mode not in (0, 1):
            raise DatasetError(f"{path}: motor {motor!r}: drive_mode must be 0 or 1, not {mode!r}")
        out[motor] = MotorRange(lo, hi, mode)
    return out


def _hint(robot_type: str) -> str:
    return (f"pass the follower's calibration (--lerobot-calibration ~/.cache/huggingface/lerobot/calibration/robots/"
            f"{robot_type}/<id>.json), or --lerobot-units degrees if it was recorded with --robot.use_degrees=true")


def derive_map(info: dict, info_path: Path, units: LeRobotUnits) -> tuple[LogMap, dict] | None:
    """The mapping of a dataset whose ``robot_type`` is a known follower, from its metadata and ``units``:
    motor names are robot joint names, units as in the module docstring, the gripper excluded from fitting.
    ``None`` for another robot type (its columns are then read as radians under their own names).

    Returns:
        ``(log_map, description)``: ``description`` (for the dataset's meta) names the robot type, the arm's
        units (``"degrees"`` or ``"range"``) and the calibration file.

    Raises:
        DatasetError: range units without a calibration, a calibration without one of the arm's motors, or no
            joint range for the gripper.
    """
    robot_type = info.get("robot_type")
    follower = FOLLOWERS.get(robot_type) if isinstance(robot_type, str) else None
    if follower is None:
        return None
    arm = [m for m in follower.motors if m != follower.gripper]
    what = units.arm or follower.default_units
    table = {}
    if what == "degrees":
        scale = math.pi / 180.0 * (TICKS_PER_TURN - 1) / TICKS_PER_TURN
        table.update({m: (scale, 0.0) for m in arm})
    else:
        if units.calibration is None:
            how = "is given in" if units.arm else "records its arm joints by default (use_degrees=false) in"
            raise DatasetError(f"{info_path}: robot_type {robot_type!r} {how} LeRobot's range units (-100..100 of "
                               f"each calibrated range), which need the calibration: {_hint(robot_type)}")
        for m in arm:
            c = units.calibration.get(m)
            if c is None:
                raise DatasetError(f"{units.calibration_file}: no motor {m!r} (it has: "
                                   f"{', '.join(units.calibration)}), needed for {info_path}")
            half_turns = (c.range_max - c.range_min) / 2 * 2 * math.pi / TICKS_PER_TURN  # rad at v = 100
            table[m] = ((-1.0 if c.drive_mode else 1.0) * half_turns / 100.0, 0.0)
    lo, hi = units.ranges.get(follower.gripper, (-math.inf, math.inf))
    if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
        raise DatasetError(f"{info_path}: the robot has no finite range for joint {follower.gripper!r}, onto which "
                           "LeRobot's 0..100 gripper opening maps")
    table[follower.gripper] = ((hi - lo) / 100.0, lo)
    calibration = units.calibration_file if what == "range" else ""
    source = f"{info_path} (robot_type {robot_type}, arm in {what} units" + \
        (f", calibration {calibration})" if calibration else ")")
    description = {"robot_type": robot_type, "arm_units": what, "calibration": calibration}
    return LogMap(units=table, exclude=(follower.gripper,), source=source), description


def check_range_units(where: str, key: str, a: np.ndarray, names: list[str], log_map: LogMap, description: dict
                      ) -> None:
    """Raise where a measured position of an arm joint recorded in range units lies outside LeRobot's [-100, 100]
    (``a`` (N, n) in ``names`` order, rows counted from 0): a dataset recorded in degrees, read as range units."""
    if description["arm_units"] != "range" or key != "observation.state":
        return
    gripper = FOLLOWERS[description["robot_type"]].gripper
    cols = [j for j, n in enumerate(names) if n != gripper and n in log_map.units]
    bad = np.abs(a[:, cols]) > 100.0 + RANGE_SLACK
    if bad.any():
        r, c = np.argwhere(bad)[0]
        j = cols[c]
        raise DatasetError(f"{where}: row {r}, {key}[{j}] ({names[j]}) = {a[r, j]:.6g} lies outside LeRobot's "
                           f"-100..100 range units: if it was recorded with --robot.use_degrees=true, pass "
                           "--lerobot-units degrees")


# ------------------------------------------------------------------------------------------------ the datasets

def lerobot_root(path) -> Path | None:
    """``path`` if it is a LeRobot dataset folder (it has ``meta/info.json``), else ``None``."""
    p = Path(path)
    return p if (p / "meta" / "info.json").is_file() else None


def read_lerobot(path, joint_names: list[str], log_map: LogMap | None = None, lerobot: LeRobotUnits | None = None
                 ) -> list[tuple[str, dict]]:
    """Every episode of a LeRobot dataset (v2.x or v3.0) as ``(name, read_log arrays)``, in episode order:
    ``t`` (N,) [s] from the ``timestamp`` column, ``q`` (N, n) from ``observation.state``, ``q_cmd`` (N, n) from
    ``action`` (both converted by the map's units, e.g. degrees), ``qd`` from ``observation.velocity`` and ``tau``
    from ``observation.effort`` where the dataset has them, else ``None``. Without ``log_map``, a follower whose
    ``robot_type`` is known gets its map from the metadata and ``lerobot`` (:func:`wresdyn.data.lerobot.derive_map`)."""
    return [(r.name, r.log) for r in read_lerobot_runs(path, joint_names, log_map, lerobot)]


def _feature_names(features: dict, key: str, info_path: Path) -> list[str] | None:
    feat = features.get(key)
    if feat is None:
        return None
    names = feat.get("names") if isinstance(feat, dict) else None
    if isinstance(names, dict) and len(names) == 1:  # v2.0 style {"motors": [...]}
        names = next(iter(names.values()))
    if not isinstance(names, list) or not names or not all(isinstance(n, str) for n in names):
        raise DatasetError(f"{info_path}: features[{key!r}] has no list of joint names (names: {names!r})")
    shape = feat.get("shape")
    if isinstance(shape, list) and shape and shape[0] != len(names):
        raise DatasetError(f"{info_path}: features[{key!r}] has shape {shape} but {len(names)} names")
    out = []
    for n in names:
        for suffix in LEROBOT_SUFFIXES:
            if n.endswith(suffix):
                n = n[: -len(suffix)]
                break
        out.append(n)
    return out


_FEATURES = {"q": "observation.state", "q_cmd": "action", "qd": "observation.velocity", "tau": "observation.effort"}


def read_lerobot_runs(root, joint_names: list[str], log_map: LogMap | None = None,
                      lerobot: LeRobotUnits | None = None) -> list[Run]:
    """:func:`read_lerobot` as :class:`~wresdyn.data.log_files.Run` records (with the format's facts and the
    derived map, if any)."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    root, log_map = Path(root), log_map or IDENTITY
    info_path = root / "meta" / "info.json"
    try:
        info = json.loads(info_path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DatasetError(f"{info_path}: not a readable JSON file: {e}") from None
    features = info.get("features") if isinstance(info, dict) else None
    if not isinstance(features, dict):
        raise DatasetError(f"{info_path}: no 'features' table")
    names = {k: _feature_names(features, f, info_path) for k, f in _FEATURES.items()}
    for k in ("q", "q_cmd"):
        if names[k] is None:
            raise DatasetError(f"{info_path}: features has no {_FEATURES[k]!r} (it has: {', '.join(features)})")
    derived = derive_map(info, info_path, lerobot or LeRobotUnits()) if log_map is IDENTITY else None
    if derived is not None:
        log_map, units_info = derived
    elif lerobot is not None and (lerobot.calibration is not None or lerobot.arm is not None):
        raise DatasetError(f"{info_path}: robot_type {info.get('robot_type')!r} is no LeRobot follower whose units "
                           f"are known ({', '.join(FOLLOWERS)}): map it with a mapping file (--map)")
    files = sorted((root / "data").rglob("*.parquet"))
    if not files:
        raise DatasetError(f"{root}: LeRobot dataset has no data/**/*.parquet file")
    parts: dict[int, list[dict]] = {}
    for file in files:
        try:
            schema = pq.read_schema(file).names
        except Exception as e:  # pyarrow raises several types on a corrupt file; report one line
            raise DatasetError(f"{file}: not a readable parquet file: {type(e).__name__}: {e}") from None
        for col in ("timestamp", _FEATURES["q"], _FEATURES["q_cmd"]):
            if col not in schema:
                raise DatasetError(f"{file}: no column {col!r} (columns: {', '.join(schema)})")
        keys = [k for k in _FEATURES if names[k] is not None and _FEATURES[k] in schema]
        table = pq.read_table(file, columns=["timestamp"] + [_FEATURES[k] for k in keys]
                              + (["episode_index"] if "episode_index" in schema else []))
        n_rows = table.num_rows
        t = table.column("timestamp").to_numpy().astype(np.float64)
        check_finite(str(file), "timestamp", t, ["'timestamp'"], np.arange(n_rows), "row")
        if "episode_index" in schema:
            ep = table.column("episode_index").to_numpy()
        else:
            m = re.search(r"episode_(\d+)", file.stem)
            if m is None:
                raise DatasetError(f"{file}: no 'episode_index' column and no episode number in the file name")
            ep = np.full(n_rows, int(m.group(1)))
        arrays = {}
        for k in keys:
            col, n = table.column(_FEATURES[k]).combine_chunks(), len(names[k])
            if col.null_count:
                r = int(np.flatnonzero(col.is_null().to_numpy(zero_copy_only=False))[0])
                raise DatasetError(f"{file}: row {r}, column {_FEATURES[k]!r} is null")
            lengths = pc.list_value_length(col).to_numpy(zero_copy_only=False)
            if (lengths != n).any():
                r = int(np.flatnonzero(lengths != n)[0])
                raise DatasetError(f"{file}: row {r}, column {_FEATURES[k]!r} has {lengths[r]} values, info.json "
                                   f"names {n}")
            a = col.flatten().to_numpy(zero_copy_only=False).astype(np.float64).reshape(n_rows, n)
            check_finite(str(file), _FEATURES[k], a, [f"{_FEATURES[k]!r}[{j}] ({names[k][j]})" for j in range(n)],
                         np.arange(n_rows), "row")
            if derived is not None:
                check_range_units(str(file), _FEATURES[k], a, names[k], log_map, units_info)
            arrays[k] = a
        order = np.argsort(ep, kind="stable")  # rows of each episode, in file order
        for rows in np.split(order, np.flatnonzero(np.diff(ep[order])) + 1):
            e = ep[rows[0]]
            check_stamps(f"{file}: episode {int(e)}", t[rows], rows, "row")
            parts.setdefault(int(e), []).append({"file": file, "rows": rows, "t": t[rows],
                                                 **{k: a[rows] for k, a in arrays.items()}})
    dataset = root.resolve().name
    runs = []
    for e in sorted(parts):
        ps = parts[e]
        for a, b in itertools.pairwise(ps):
            if not b["t"][0] > a["t"][-1]:
                raise DatasetError(f"{b['file']}: episode {e}: time stamp at row {b['rows'][0]} is not after the "
                                   f"episode's previous row in {a['file'].name}")
        cat = {k: np.concatenate([p[k] for p in ps]) if all(k in p for p in ps) else None
               for k in ("t", "q", "q_cmd", "qd", "tau")}
        mapped = {}
        for k in ("q", "q_cmd", "qd", "tau"):
            if cat[k] is not None:
                mapped.update(map_joints(names[k], {k: cat[k]}, joint_names, log_map, f"{info_path}: {_FEATURES[k]}"))
            else:
                mapped[k] = None
        if log_map.velocity == "derived":
            mapped["qd"] = None
        log = {"t": cat["t"], **mapped}
        runs.append(Run(f"{dataset}_ep{e}", "lerobot", str(root), log,
                        {"format": "lerobot", "codebase_version": info.get("codebase_version"), "fps": info.get("fps"),
                         "episode_index": e, **({"units": units_info} if derived is not None else {})},
                        log_map if derived is not None else None))
    return runs
