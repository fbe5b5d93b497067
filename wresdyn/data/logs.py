"""Import real-robot logs (CSV or NPZ) into :class:`~wresdyn.data.dataset.Trajectory` on the simulation step.

Joints are mapped by name to the robot's order. A log may be recorded at any rate (typically 50-1000 Hz) and
with clock jitter; it is brought onto the uniform grid t_k = k / rate_hz (k = 0 at the log's first time
stamp, up to its last): measured positions, velocities and torques are interpolated linearly, commands are
held (zero-order hold: the command in force at t_k is the last one logged at or before t_k), and q̈ is
derived from the resampled q̇ (:func:`~wresdyn.data.dataset.derive_qdd`). Column conventions: docs/dataset.md.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .dataset import SPLITS, Dataset, DatasetError, Trajectory, derive_qdd

__all__ = ["read_log", "resample", "import_log", "import_logs"]

_ZOH_EPS = 1e-6
"""A grid time within this fraction of a step after a logged command time counts as at or after it, so
float rounding of k / rate never holds the previous command one log sample too long."""


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
        try:
            data[i] = [float(x) for x in r]
        except ValueError:
            raise DatasetError(f"{path}: data row {i + 1} has a field that is not a number") from None
    return {h: data[:, j] for j, h in enumerate(header)}


def read_log(path, joint_names: list[str]) -> dict[str, np.ndarray | None]:
    """Read a CSV or NPZ log into arrays in ``joint_names`` order, at the log's own time stamps.

    Returns:
        ``{"t": (N,) [s], "q": (N, n) [rad], "qd": (N, n) [rad/s] or None, "q_cmd": (N, n) [rad],
        "tau": (N, n) [N*m] or None}``.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(f"{path}: log file not found")
    if path.suffix.lower() == ".csv":
        out = _from_columns(_csv_columns(path), joint_names, path)
    elif path.suffix.lower() == ".npz":
        out = _from_npz(path, joint_names)
    else:
        raise DatasetError(f"{path}: unknown log type {path.suffix!r} (expected .csv or .npz)")
    t = out["t"]
    for key, a in out.items():
        if a is not None and not np.isfinite(a).all():
            row = int(np.flatnonzero(~np.isfinite(a.reshape(len(t), -1)).all(axis=1))[0])
            raise DatasetError(f"{path}: {key} has NaN/inf at data row {row + 1}")
    dt = np.diff(t)
    if (dt <= 0).any():
        row = int(np.flatnonzero(dt <= 0)[0]) + 1
        what = "duplicated" if dt[row - 1] == 0 else "decreasing"
        raise DatasetError(f"{path}: {what} time stamp at data row {row + 1} (t = {t[row]:.6g} s)")
    return out


def _from_columns(cols: dict[str, np.ndarray], joint_names: list[str], path: Path) -> dict:
    if "time" not in cols:
        raise DatasetError(f"{path}: no 'time' column")
    found: dict[str, dict[str, np.ndarray]] = {"q": {}, "qd": {}, "q_cmd": {}, "tau": {}}
    unknown = []
    for name, values in cols.items():
        if name == "time":
            continue
        for prefix, kind in (("q_cmd_", "q_cmd"), ("qd_", "qd"), ("tau_", "tau"), ("q_", "q")):
            if name.startswith(prefix) and name[len(prefix):] in joint_names:
                joint = name[len(prefix):]
                break
        else:
            kind, joint = "q", name
        if joint not in joint_names:
            unknown.append(name)
        elif joint in found[kind]:
            raise DatasetError(f"{path}: joint {joint!r} has two {kind} columns ({joint} and q_{joint})")
        else:
            found[kind][joint] = values
    if unknown:
        raise DatasetError(f"{path}: column(s) {unknown} name no joint of the robot")
    out = {"t": cols["time"]}
    for kind, required in (("q", True), ("q_cmd", True), ("qd", False), ("tau", False)):
        got = found[kind]
        missing = [j for j in joint_names if j not in got]
        if missing and (required or got):
            col = "q_<joint> (or <joint>)" if kind == "q" else f"{kind}_<joint>"
            raise DatasetError(f"{path}: missing {col} column(s) for joint(s) {missing}")
        out[kind] = np.stack([got[j] for j in joint_names], axis=1) if got else None
    return out


def _from_npz(path: Path, joint_names: list[str]) -> dict:
    try:
        with np.load(path, allow_pickle=False) as z:
            files = {k: z[k] for k in z.files}
    except Exception as e:  # numpy raises several types on a corrupt zip; report one line
        raise DatasetError(f"{path}: not a readable NPZ log: {type(e).__name__}") from None
    for key in ("time", "joint_names", "q", "q_cmd"):
        if key not in files:
            raise DatasetError(f"{path}: NPZ log has no {key!r} array")
    names = [str(n) for n in files["joint_names"].reshape(-1)]
    unknown = [n for n in names if n not in joint_names]
    missing = [n for n in joint_names if n not in names]
    if unknown:
        raise DatasetError(f"{path}: joint(s) {unknown} name no joint of the robot")
    if missing:
        raise DatasetError(f"{path}: joint(s) {missing} of the robot are missing")
    t = np.asarray(files["time"], dtype=np.float64).reshape(-1)
    cols = [names.index(j) for j in joint_names]
    out = {"t": t}
    for key in ("q", "q_cmd", "qd", "tau"):
        a = files.get(key)
        if a is not None:
            if a.shape != (len(t), len(names)):
                raise DatasetError(f"{path}: {key} has shape {a.shape}, expected ({len(t)}, {len(names)}) "
                                   "(T, n_joints)")
            a = np.asarray(a, dtype=np.float64)[:, cols]
        out[key] = a
    return out


def resample(log: dict, rate_hz: float) -> dict[str, np.ndarray | None]:
    """Bring a log onto t_k = k / rate_hz (k = 0 at the first log time stamp): linear interpolation of measured
    q, q̇ and τ, zero-order hold of q_cmd. Without a logged q̇ it is the derivative of q (second-order
    differences on the log's own time stamps), interpolated the same way. Returns the :func:`read_log` keys
    (``t`` starting at 0) plus ``qdd``."""
    t_log = log["t"] - log["t"][0]
    t = np.arange(int(np.floor(t_log[-1] * rate_hz + _ZOH_EPS)) + 1) / rate_hz
    qd_log = log["qd"] if log["qd"] is not None else np.gradient(log["q"], t_log, axis=0)

    def lerp(a):
        return None if a is None else np.stack([np.interp(t, t_log, a[:, j]) for j in range(a.shape[1])], axis=1)

    held = np.searchsorted(t_log, t + _ZOH_EPS / rate_hz, side="right") - 1
    qd = lerp(qd_log)
    return {"t": t, "q": lerp(log["q"]), "qd": qd, "qdd": derive_qdd(qd, rate_hz), "q_cmd": log["q_cmd"][held],
            "tau": lerp(log["tau"])}


def import_log(path, robot, rate_hz: float = 500.0, split: str = "heldout", name: str | None = None) -> Trajectory:
    """Read one log (CSV or NPZ) and resample it onto the simulation step. See docs/dataset.md for columns."""
    return _import(path, robot, rate_hz, split, name)[0]


def _import(path, robot, rate_hz, split, name=None) -> tuple[Trajectory, dict]:
    if split not in SPLITS:
        raise DatasetError(f"{path}: unknown split {split!r}; choose from {SPLITS}")
    log = read_log(path, list(robot.joint_names))
    if (log["t"][-1] - log["t"][0]) * rate_hz < 1:
        raise DatasetError(f"{path}: log is shorter than one simulation step")
    r = resample(log, rate_hz)
    info = {"file": str(path), "samples": len(log["t"]), "median_rate_hz": float(1.0 / np.median(np.diff(log["t"])))}
    return Trajectory(name or Path(path).stem, split, r["t"], r["q"], r["qd"], r["qdd"], r["q_cmd"], r["tau"]), info


def import_logs(paths, robot, rate_hz: float = 500.0, split: str = "heldout") -> Dataset:
    """A :class:`~wresdyn.data.dataset.Dataset` of real logs (no mismatch, no seed), one trajectory per file, named
    after the file (made unique with its index when two files share a stem)."""
    trajs, sources = [], []
    for p in paths:
        tr, info = _import(p, robot, rate_hz, split)
        trajs.append(tr)
        sources.append(info)
    names = [tr.name for tr in trajs]
    for i, tr in enumerate(trajs):
        if names.count(tr.name) > 1:
            tr.name = f"{tr.name}_{i}"
    ds = Dataset(list(robot.joint_names), float(rate_hz), trajs, str(robot.source), robot.source_sha256, {}, None,
                 {"source_logs": sources})
    ds.validate("imported logs")
    return ds
