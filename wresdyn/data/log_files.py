"""One CSV or NPZ log read into robot joint order: the core every log format shares.

Joints are mapped by name to the robot's order, through an optional mapping file (:class:`LogMap`: log name →
robot joint, units, joints excluded from the fit). A log may be recorded at any rate (typically 50-1000 Hz) and
with clock jitter, and its commands may carry time stamps of their own; :mod:`wresdyn.data.log_resample` brings it
onto the uniform grid t_k = k / rate_hz (k = 0 at the first state stamp at which a command is in force, up to the
last state stamp): measured positions, velocities and torques are interpolated linearly, commands are held
(zero-order hold: the command in force at t_k is the last one logged at or before t_k), and q̈ is derived from the
resampled q̇ (:func:`~wresdyn.data.dataset.derive_qdd`). The SAGE and LeRobot formats, format detection and
multi-run datasets with split assignment are in :mod:`wresdyn.data.importers`; :mod:`wresdyn.data.logs` reads a log
of any format. Column conventions and the mapping file: docs/dataset.md.
"""

from __future__ import annotations

import csv
import fnmatch
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomllib

from .dataset import DatasetError

__all__ = ["Run", "LogMap", "IDENTITY", "UNIT_SCALES", "read_toml", "map_joints", "check_finite", "check_stamps",
           "read_file"]

UNIT_SCALES = {"rad": 1.0, "deg": math.pi / 180.0}
"""Named position units of the mapping file: value [rad] = scale * logged value."""


def read_toml(path: Path, what: str) -> dict:
    """A TOML file's contents; a missing or unreadable file is a one-line :class:`DatasetError` naming ``what``."""
    try:
        with open(path, "rb") as f:
            return tomllib.load(f)
    except FileNotFoundError:
        raise DatasetError(f"{path}: {what} not found") from None
    except (OSError, tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path}: not a readable TOML {what}: {e}") from None


@dataclass(frozen=True)
class LogMap:
    """How a log's joints become the robot's: the mapping file (TOML) of docs/dataset.md, "Mapping file".

    Every lookup takes the log's joint name and the robot joint it maps to; a pattern matches either.
    """

    joints: dict[str, str] = field(default_factory=dict)
    """Log joint name -> robot joint name; a log name not listed is taken as a robot joint name."""
    units: dict[str, tuple[float, float]] = field(default_factory=dict)
    """Log or robot joint name, or fnmatch pattern -> (scale, offset): position [rad] = scale * logged + offset,
    velocity [rad/s] = scale * logged (torques are kept as logged). An exact name wins over patterns, patterns
    are tried in file order; no match: radians (1, 0)."""
    exclude: tuple[str, ...] = ()
    """fnmatch patterns of robot joints not fitted: still imported with their recorded values, listed in the
    dataset's ``meta["excluded_joints"]``."""
    ignore: tuple[str, ...] = ()
    """fnmatch patterns of log joints that are no joint of the robot: dropped on import."""
    velocity: str = "logged"
    """``"logged"``: use a logged q̇ when there is one; ``"derived"``: always differentiate q."""
    source: str = ""
    """File the map was read from ("" for the identity map), for messages."""

    @classmethod
    def load(cls, path) -> LogMap:
        """Read and check a mapping file; every error is one line naming the file and the key."""
        path = Path(path)
        raw = read_toml(path, "mapping file")
        unknown = sorted(set(raw) - {"joints", "units", "exclude", "velocity"})
        if unknown:
            raise DatasetError(f"{path}: unknown key(s) {unknown} (expected [joints], [units], [exclude], velocity)")
        joints = _table(raw, "joints", path)
        for k, v in joints.items():
            if not isinstance(v, str) or not v:
                raise DatasetError(f"{path}: [joints] {k} must be a robot joint name (a string), not {v!r}")
        targets = list(joints.values())
        dup = sorted({v for v in targets if targets.count(v) > 1})
        if dup:
            raise DatasetError(f"{path}: [joints] maps several log joints onto {dup}")
        units = {k: _unit(v, f"{path}: [units] {k}") for k, v in _table(raw, "units", path).items()}
        exclude = _table(raw, "exclude", path)
        bad = sorted(set(exclude) - {"joints", "ignore"})
        if bad:
            raise DatasetError(f"{path}: unknown key(s) {bad} in [exclude] (expected joints, ignore)")
        lists = {}
        for key in ("joints", "ignore"):
            v = exclude.get(key, [])
            if not isinstance(v, list) or not all(isinstance(x, str) and x for x in v):
                raise DatasetError(f"{path}: [exclude] {key} must be a list of joint names or patterns, not {v!r}")
            lists[key] = tuple(v)
        velocity = raw.get("velocity", "logged")
        if velocity not in ("logged", "derived"):
            raise DatasetError(f"{path}: velocity must be \"logged\" or \"derived\", not {velocity!r}")
        return cls(dict(joints), units, lists["joints"], lists["ignore"], velocity, str(path))

    def robot_name(self, log_name: str) -> str:
        """The robot joint a log joint maps to."""
        return self.joints.get(log_name, log_name)

    def unit(self, log_name: str, robot_name: str) -> tuple[float, float]:
        """(scale, offset) of a joint: position [rad] = scale * logged + offset."""
        for name in (log_name, robot_name):
            if name in self.units:
                return self.units[name]
        for pattern, unit in self.units.items():
            if fnmatch.fnmatchcase(log_name, pattern) or fnmatch.fnmatchcase(robot_name, pattern):
                return unit
        return 1.0, 0.0

    def ignored(self, log_name: str) -> bool:
        return any(fnmatch.fnmatchcase(log_name, p) for p in self.ignore)

    def excluded_joints(self, joint_names: list[str]) -> list[str]:
        """The robot joints (of ``joint_names``, in that order) that [exclude] joints keeps out of the fit."""
        log_of = {v: k for k, v in self.joints.items()}
        return [j for j in joint_names
                if any(fnmatch.fnmatchcase(j, p) or fnmatch.fnmatchcase(log_of.get(j, j), p) for p in self.exclude)]

    def check(self, joint_names: list[str], robot_label: str) -> None:
        """Every [joints] target must be a joint of the robot."""
        bad = {k: v for k, v in self.joints.items() if v not in joint_names}
        if bad:
            k, v = next(iter(bad.items()))
            raise DatasetError(f"{self.source}: [joints] {k} = {v!r}: {v!r} is not a joint of {robot_label} "
                               f"(its joints: {', '.join(joint_names)})")

    def to_dict(self) -> dict:
        """JSON-serialisable summary for the dataset's meta."""
        return {"file": self.source, "joints": dict(self.joints), "units": {k: list(v) for k, v in self.units.items()},
                "exclude": list(self.exclude), "ignore": list(self.ignore), "velocity": self.velocity}


def _table(raw: dict, key: str, path: Path) -> dict:
    v = raw.get(key, {})
    if not isinstance(v, dict):
        raise DatasetError(f"{path}: {key} must be a table ([{key}]), not {v!r}")
    return v


def _unit(v, where: str) -> tuple[float, float]:
    if isinstance(v, str):
        if v not in UNIT_SCALES:
            raise DatasetError(f"{where} = {v!r}: unknown unit (expected {', '.join(map(repr, UNIT_SCALES))} or "
                               "{scale = ..., offset = ...})")
        return UNIT_SCALES[v], 0.0
    if isinstance(v, dict) and v and set(v) <= {"scale", "offset"}:
        scale, offset = v.get("scale", 1.0), v.get("offset", 0.0)
        ok = all(isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x) for x in (scale, offset))
        if ok and scale != 0:
            return float(scale), float(offset)
    raise DatasetError(f"{where} = {v!r}: expected \"rad\", \"deg\" or "
                       "{scale = <non-zero number>, offset = <number>}")


IDENTITY = LogMap()
"""No renaming, radians, nothing excluded."""


@dataclass
class Run:
    """One log read into robot order, before resampling."""

    name: str
    """Trajectory name: the file stem, the SAGE run folder, or ``<dataset>_ep<k>``."""
    format: str
    """``"csv"``, ``"npz"``, ``"mcap"``, ``"sage"`` or ``"lerobot"``."""
    file: str
    """File or folder it was read from."""
    log: dict
    """:func:`~wresdyn.data.logs.read_log` arrays (``t``, ``q``, ``qd``, ``q_cmd``, ``tau``, optional ``t_cmd``)."""
    info: dict = field(default_factory=dict)
    """Format-specific facts for the dataset's meta (trimmed seconds, LeRobot fps and version, ...)."""
    log_map: LogMap | None = None
    """The mapping it was read with where it came from the log's own metadata (a LeRobot follower), else ``None``."""


def map_joints(names: list[str], arrays: dict, joint_names: list[str], log_map: LogMap, where: str) -> dict:
    """Arrays with columns in the log's joint order (``names``) -> the robot's order, in SI units.

    Args:
        names: log joint names, the columns of every array, shape (n_log,).
        arrays: ``{"q" | "q_cmd": (N, n_log) positions, "qd": (N, n_log) velocities, "tau": (N, n_log)}`` in log
            units (``None`` values pass through).
        where: "file: what" prefix of the error messages.

    Returns:
        The same keys, shape (N, n_dof) in ``joint_names`` order: positions [rad], velocities [rad/s], torques as
        logged.
    """
    cols, unknown = {}, []
    for i, n in enumerate(names):
        robot = log_map.robot_name(n)
        if robot in joint_names:
            if robot in cols:
                raise DatasetError(f"{where}: joints {names[cols[robot]]!r} and {n!r} both map onto {robot!r}")
            cols[robot] = i
        elif not log_map.ignored(n):
            unknown.append(n)
    if unknown:
        mapped = f"mapped in {log_map.source}" if log_map.source else "mapped (no mapping file given)"
        raise DatasetError(f"{where}: joint(s) {unknown} are neither joints of the robot nor {mapped}")
    missing = [j for j in joint_names if j not in cols]
    if missing:
        raise DatasetError(f"{where}: joint(s) {missing} of the robot are missing")
    idx = [cols[j] for j in joint_names]
    units = np.array([log_map.unit(names[cols[j]], j) for j in joint_names])  # (n_dof, 2)
    out = {}
    for key, a in arrays.items():
        if a is None:
            out[key] = None
            continue
        a = np.asarray(a, dtype=np.float64)[:, idx]
        if key in ("q", "q_cmd"):
            a = a * units[:, 0] + units[:, 1]
        elif key == "qd":
            a = a * units[:, 0]
        out[key] = a
    return out


def check_finite(where: str, key: str, a: np.ndarray, columns: list[str], rows=None, row_word: str = "data row"):
    """Raise naming the first row and column of ``a`` (N, n) that is NaN or inf; ``rows`` (N,) gives each
    sample's row number in its file (default: sample index + 1)."""
    a = a.reshape(len(a), -1)
    bad = ~np.isfinite(a)
    if bad.any():
        r, c = np.argwhere(bad)[0]
        row = int(rows[r]) if rows is not None else int(r) + 1
        raise DatasetError(f"{where}: {key} has NaN/inf at {row_word} {row} (column {columns[c]}: {a[r, c]!r})")


def check_stamps(where: str, t: np.ndarray, rows=None, row_word: str = "data row") -> None:
    """Raise naming the first row whose time stamp [s] is not after the previous one."""
    dt = np.diff(t)
    if (dt <= 0).any():
        k = int(np.flatnonzero(dt <= 0)[0]) + 1
        row = int(rows[k]) if rows is not None else k + 1
        what = "duplicated" if dt[k - 1] == 0 else "decreasing"
        raise DatasetError(f"{where}: {what} time stamp at {row_word} {row} (t = {t[k]:.6g} s)")


def _csv_columns(path: Path) -> dict[str, np.ndarray]:
    try:
        with open(path, newline="", encoding="utf-8") as f:
            rows = [r for r in csv.reader(f) if r and not r[0].lstrip().startswith("#")]
    except (OSError, UnicodeDecodeError) as e:
        raise DatasetError(f"{path}: cannot read CSV: {e}") from None
    if len(rows) < 3:
        raise DatasetError(f"{path}: a CSV log needs a header row and at least two data rows")
    header = [h.strip() for h in rows[0]]
    dup = sorted({h for h in header if header.count(h) > 1})
    if dup:
        raise DatasetError(f"{path}: duplicated column(s) {dup}")
    data = np.empty((len(rows) - 1, len(header)))
    for i, r in enumerate(rows[1:]):
        if len(r) != len(header):
            raise DatasetError(f"{path}: data row {i + 1} has {len(r)} fields, the header {len(header)}")
        for j, x in enumerate(r):
            try:
                data[i, j] = float(x)
            except ValueError:
                hint = " (a SAGE log: pass its run folder)" if header[:2] == ["type", "timestamp"] else ""
                raise DatasetError(f"{path}: data row {i + 1}, column {j + 1} ({header[j]!r}): {x!r} is not a "
                                   f"number{hint}") from None
    return {h: data[:, j] for j, h in enumerate(header)}


def read_file(path, joint_names: list[str], log_map: LogMap | None = None) -> dict[str, np.ndarray | None]:
    """Read one CSV or NPZ log into arrays in ``joint_names`` order, at the log's own time stamps.

    Returns:
        ``{"t": (N,) [s], "q": (N, n) [rad], "qd": (N, n) [rad/s] or None, "q_cmd": (N, n) [rad],
        "tau": (N, n) [N*m] or None}``.
    """
    log_map = log_map or IDENTITY
    path = Path(path)
    if path.is_dir():
        raise DatasetError(f"{path}: a folder but no SAGE run (control.csv, state_motor.csv); LeRobot datasets and "
                           "folders of runs are read by import_logs (wresdyn collect --logs)")
    if not path.is_file():
        raise DatasetError(f"{path}: log file not found")
    if path.suffix.lower() == ".csv":
        out, labels = _from_columns(_csv_columns(path), joint_names, path, log_map)
    elif path.suffix.lower() == ".npz":
        out, labels = _from_npz(path, joint_names, log_map)
    else:
        raise DatasetError(f"{path}: unknown log type {path.suffix!r} (expected .csv, .npz or .mcap, a SAGE run "
                           "folder or a LeRobot dataset folder)")
    t = out["t"]
    check_finite(str(path), "time", t, ["time"])
    for key, a in out.items():
        if a is not None and key != "t":
            check_finite(str(path), key, a, labels[key])
    check_stamps(str(path), t)
    if log_map.velocity == "derived":
        out["qd"] = None
    return out


def _from_columns(cols: dict[str, np.ndarray], joint_names: list[str], path: Path, log_map: LogMap):
    if "time" not in cols:
        raise DatasetError(f"{path}: no 'time' column")
    found: dict[str, dict[str, tuple[str, str, np.ndarray]]] = {"q": {}, "qd": {}, "q_cmd": {}, "tau": {}}
    unknown = []
    for name, values in cols.items():
        if name == "time":
            continue
        for prefix, kind in (("q_cmd_", "q_cmd"), ("qd_", "qd"), ("tau_", "tau"), ("q_", "q")):
            if name.startswith(prefix) and log_map.robot_name(name[len(prefix):]) in joint_names:
                log_name = name[len(prefix):]
                break
        else:
            kind, log_name = "q", name
        joint = log_map.robot_name(log_name)
        if joint not in joint_names:
            if not log_map.ignored(log_name):
                unknown.append(name)
        elif joint in found[kind]:
            raise DatasetError(f"{path}: joint {joint!r} has two {kind} columns ({found[kind][joint][0]} and {name})")
        else:
            found[kind][joint] = (name, log_name, values)
    if unknown:
        mapped = f" nor are mapped in {log_map.source}" if log_map.source else ""
        raise DatasetError(f"{path}: column(s) {unknown} name no joint of the robot{mapped}")
    out, labels = {"t": cols["time"]}, {}
    for kind, required in (("q", True), ("q_cmd", True), ("qd", False), ("tau", False)):
        got = found[kind]
        missing = [j for j in joint_names if j not in got]
        if missing and (required or got):
            col = "q_<joint> (or <joint>)" if kind == "q" else f"{kind}_<joint>"
            raise DatasetError(f"{path}: missing {col} column(s) for joint(s) {missing}")
        if not got:
            out[kind] = None
            continue
        labels[kind] = [repr(got[j][0]) for j in joint_names]
        a = np.stack([got[j][2] for j in joint_names], axis=1)
        units = np.array([log_map.unit(got[j][1], j) for j in joint_names])
        out[kind] = a * units[:, 0] + units[:, 1] if kind in ("q", "q_cmd") else a * units[:, 0] if kind == "qd" else a
    return out, labels


def _from_npz(path: Path, joint_names: list[str], log_map: LogMap):
    try:
        with np.load(path, allow_pickle=False) as z:
            files = {k: z[k] for k in z.files}
    except Exception as e:  # numpy raises several types on a corrupt zip; report one line
        raise DatasetError(f"{path}: not a readable NPZ log: {type(e).__name__}") from None
    for key in ("time", "joint_names", "q", "q_cmd"):
        if key not in files:
            raise DatasetError(f"{path}: NPZ log has no {key!r} array")
    names = [str(n) for n in files["joint_names"].reshape(-1)]
    t = np.asarray(files["time"], dtype=np.float64).reshape(-1)
    arrays = {}
    for key in ("q", "q_cmd", "qd", "tau"):
        a = files.get(key)
        if a is not None and a.shape != (len(t), len(names)):
            raise DatasetError(f"{path}: {key} has shape {a.shape}, expected ({len(t)}, {len(names)}) (T, n_joints)")
        arrays[key] = a
    out = {"t": t, **map_joints(names, arrays, joint_names, log_map, f"{path}: joint_names")}
    labels = {key: [f"{key}[:, {names.index(log_name)}] ({log_name})" for log_name in _log_names(names, joint_names,
                                                                                                   log_map)]
              for key in arrays}
    return out, labels


def _log_names(names: list[str], joint_names: list[str], log_map: LogMap) -> list[str]:
    """The log joint name of each robot joint (after :func:`map_joints` checked the mapping)."""
    by_robot = {log_map.robot_name(n): n for n in names}
    return [by_robot[j] for j in joint_names]
