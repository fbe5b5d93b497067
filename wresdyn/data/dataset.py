"""Recorded joint-state trajectories: the data the residual learners fit, and its file format.

A :class:`Dataset` is a set of :class:`Trajectory` sampled at one rate, with the joint order, the robot file
(and its SHA-256) they were recorded on, the gains config applied on top of that file (if any: its content
travels with the data, so every later command replays on the same robot), the mismatch config of the "real"
robot (empty for real logs), the seed and free-form metadata. Sample k holds the state (q[k], q̇[k]) at t[k];
applying q_cmd[k] for one step of 1 / rate_hz gives the state at k + 1. Only joint states and commands feed
the learners; a measured torque may ride along for diagnostics.

On disk a dataset is one ``.npz`` (zip) file: a UTF-8 JSON ``header`` and per-trajectory arrays
``traj/<index>/<field>``; docs/dataset.md describes it. Arrays are stored as float32 where that is exact and
float64 otherwise, and always loaded as float64, so a save / load round trip is exact. Loading validates
everything and raises :class:`DatasetError` with a one-line message naming the file and the problem; the header's
checks and the schema versions are :mod:`wresdyn.data.dataset_header`'s.
"""

from __future__ import annotations

import json
import os
import tempfile
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import WresdynError
from .dataset_header import (FORMAT, READ_VERSIONS, SCHEMA_VERSION, DatasetError, check_gains, header_from,
                             npz_failure, read_header)
from .savgol import savgol_filter  # scipy.signal's filter without importing scipy.signal (most of SciPy)

__all__ = ["SCHEMA_VERSION", "READ_VERSIONS", "SPLITS", "UNITS", "DatasetError", "Trajectory", "Dataset",
           "load_dataset", "read_header", "derive_qdd", "fitted_mask", "MOVING_SPEED"]

SPLITS = READ_VERSIONS[SCHEMA_VERSION]
"""Trajectory splits: training; validation (same motion family as train: every choice of hyper-parameters,
early stopping or sweep is made on it); held-out (same family) and out-of-distribution (other families), both
for reporting only."""
UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "q_cmd": "rad", "tau": "N*m"}
"""Units of the array fields (prismatic joints: m, m/s, m/s^2, N)."""
RATE_RTOL = 1e-3
"""Every time step must equal 1 / rate_hz within this fraction of a step: a log with more clock jitter is
not uniformly sampled and must be resampled first (:mod:`wresdyn.data.logs`)."""
MOVING_SPEED = 0.1
"""|q̇| above which a recorded joint counts as moving [rad/s] (five times the default velocity noise): how much
of a recording excites a joint, for the identification report and the identifiability flags."""
QDD_WINDOW = 0.022
"""Length of the Savitzky-Golay window that differentiates q̇ into q̈ [s] (11 samples at 500 Hz)."""

_FIELDS = ("t", "q", "qd", "qdd", "q_cmd", "tau")


@dataclass
class Trajectory:
    """One recorded trajectory. Arrays are converted to float64 on construction."""

    name: str
    """Unique name within the dataset."""
    split: str
    """One of :data:`SPLITS`."""
    t: np.ndarray
    """Time [s], shape (T,), uniform at 1 / rate_hz, strictly increasing."""
    q: np.ndarray
    """Measured joint positions [rad], shape (T, n_dof)."""
    qd: np.ndarray
    """Measured joint velocities [rad/s], shape (T, n_dof)."""
    qdd: np.ndarray
    """Joint accelerations derived from qd by filtered finite differences (:func:`derive_qdd`) [rad/s^2],
    shape (T, n_dof)."""
    q_cmd: np.ndarray
    """Commanded joint positions [rad], shape (T, n_dof); q_cmd[k] is held from t[k] to t[k+1]."""
    tau: np.ndarray | None = None
    """Measured joint torque [N*m], shape (T, n_dof), for diagnostics only: learners never read it."""

    def __post_init__(self):
        for name in _FIELDS:
            value = getattr(self, name)
            if value is not None:
                setattr(self, name, np.asarray(value, dtype=np.float64))

    @property
    def n_samples(self) -> int:
        return len(self.t)


def derive_qdd(qd: np.ndarray, rate_hz: float) -> np.ndarray:
    """Joint accelerations from velocities, as a real robot gets them: a Savitzky-Golay first derivative
    (quadratic fit over :data:`QDD_WINDOW`, at least 5 samples), i.e. finite differences low-passed without
    phase lag. Shape (T, n_dof) [rad/s^2]."""
    qd = np.asarray(qd, dtype=np.float64)
    window = max(5, int(round(QDD_WINDOW * rate_hz)) | 1)
    if len(qd) < window:
        return np.gradient(qd, 1.0 / rate_hz, axis=0) if len(qd) > 1 else np.zeros_like(qd)
    return savgol_filter(qd, window, polyorder=2, deriv=1, delta=1.0 / rate_hz)


@dataclass
class Dataset:
    """Trajectories recorded on one robot at one rate."""

    joint_names: list[str]
    """Joint names, the column order of every (T, n_dof) array."""
    rate_hz: float
    """Sample rate [Hz]; t[k+1] - t[k] = 1 / rate_hz."""
    trajectories: list[Trajectory]
    """All trajectories, every split."""
    robot_file: str
    """Robot file the data was recorded on (as given, usually relative to the repository root)."""
    robot_sha256: str
    """SHA-256 of that robot file's bytes."""
    mismatch: dict = field(default_factory=dict)
    """Mismatch config of the simulated real robot (:class:`wresdyn.data.mismatch.Mismatch` fields); empty for
    real logs."""
    seed: int | None = None
    """Seed the data was generated with (``None`` for real logs)."""
    meta: dict = field(default_factory=dict)
    """Free-form JSON-serialisable metadata: generator parameters, gap figures, source logs."""
    gains: dict | None = None
    """The gains config the robot was loaded with, ``{"file": path as given or None, "config": parsed TOML}``
    (:meth:`~wresdyn.robot.description.Robot.gains_record`); ``None`` when the robot file was used as it is.
    Optional header field ``gains`` (absent in files without it, which stay readable by older wresdyn);
    :func:`~wresdyn.data.loading.load_data` re-applies it."""

    @property
    def n_dof(self) -> int:
        return len(self.joint_names)

    def split(self, name: str) -> list[Trajectory]:
        """Trajectories of one split, in file order."""
        if name not in SPLITS:
            raise DatasetError(f"unknown split {name!r}; choose from {SPLITS}")
        return [tr for tr in self.trajectories if tr.split == name]

    @property
    def excluded_joints(self) -> list[str]:
        """Joints kept out of the fit and out of every error metric, in :attr:`joint_names` order: the mapping
        file's ``[exclude]`` (``meta["excluded_joints"]``, e.g. the SO-101 gripper); ``[]`` when there is none.
        They are still replayed with their recorded commands."""
        excluded = self.meta.get("excluded_joints") or []
        return [j for j in self.joint_names if j in excluded]

    @property
    def fitted_joints(self) -> list[str]:
        """The joints every learner fits and every metric averages over: all but :attr:`excluded_joints`."""
        excluded = self.excluded_joints
        return [j for j in self.joint_names if j not in excluded]

    def fit_weights(self) -> np.ndarray:
        """Per-joint weight of the fit losses and error metrics, shape (n_dof,) in :attr:`joint_names` order:
        1.0 for a fitted joint, 0.0 for an excluded one (:attr:`excluded_joints`)."""
        excluded = set(self.excluded_joints)
        return np.array([0.0 if j in excluded else 1.0 for j in self.joint_names])

    @property
    def gains_config(self) -> dict | None:
        """The stored gains config (parsed TOML) to load the robot with, ``None`` when there is none."""
        return None if self.gains is None else self.gains["config"]

    def validate(self, where: str = "dataset") -> None:
        """Check names, rate, shapes, finiteness and time stamps; raise :class:`DatasetError` naming ``where``."""
        check_gains(self.gains, where)
        names = self.joint_names
        if not names or not all(isinstance(n, str) and n for n in names):
            raise DatasetError(f"{where}: joint_names must be a non-empty list of non-empty strings")
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise DatasetError(f"{where}: duplicated joint name(s) {dup}")
        if isinstance(self.rate_hz, bool) or not isinstance(self.rate_hz, (int, float)) or not (
                np.isfinite(self.rate_hz) and self.rate_hz > 0):
            raise DatasetError(f"{where}: rate_hz must be a positive number, not {self.rate_hz!r}")
        excluded = self.meta.get("excluded_joints") if isinstance(self.meta, dict) else None
        if excluded is not None:
            if not isinstance(excluded, list) or not all(isinstance(j, str) for j in excluded):
                raise DatasetError(f"{where}: meta excluded_joints must be a list of joint names, not {excluded!r}")
            unknown = [j for j in excluded if j not in names]
            if unknown:
                raise DatasetError(f"{where}: meta excluded_joints names {unknown}, which are not among the joints "
                                   f"{names}")
            if set(names) <= set(excluded):
                raise DatasetError(f"{where}: meta excluded_joints excludes every joint; nothing is left to fit")
        if not isinstance(self.trajectories, list) or not self.trajectories:
            raise DatasetError(f"{where}: no trajectories")
        seen = set()
        for tr in self.trajectories:
            if not isinstance(tr.name, str) or not tr.name or tr.name in seen:
                raise DatasetError(f"{where}: trajectory names must be unique non-empty strings ({tr.name!r})")
            seen.add(tr.name)
            if tr.split not in SPLITS:
                raise DatasetError(f"{where}: trajectory {tr.name!r} has unknown split {tr.split!r}; "
                                   f"expected one of {SPLITS}")
            self._check_arrays(tr, where)

    def _check_arrays(self, tr: Trajectory, where: str) -> None:
        n, label = self.n_dof, f"{where}: trajectory {tr.name!r}"
        if tr.t.ndim != 1 or len(tr.t) < 2:
            raise DatasetError(f"{label}: t must have shape (T,) with T >= 2, got {tr.t.shape}")
        t_len = len(tr.t)
        for name in _FIELDS[1:]:
            a = getattr(tr, name)
            if a is None and name == "tau":
                continue
            if a is None or a.shape != (t_len, n):
                got = None if a is None else a.shape
                raise DatasetError(f"{label}: {name} must have shape ({t_len}, {n}) (T, n_dof), got {got}")
        for name in _FIELDS:
            a = getattr(tr, name)
            if a is not None and not np.isfinite(a).all():
                bad = np.flatnonzero(~np.isfinite(a).reshape(t_len, -1).all(axis=1))
                raise DatasetError(f"{label}: {name} has NaN/inf in {len(bad)} row(s), first at row {bad[0]}")
        dt = np.diff(tr.t)
        if (dt == 0).any():
            k = int(np.flatnonzero(dt == 0)[0]) + 1
            raise DatasetError(f"{label}: duplicated time stamp t = {tr.t[k]:.6g} s at row {k}")
        if (dt < 0).any():
            k = int(np.flatnonzero(dt < 0)[0]) + 1
            raise DatasetError(f"{label}: time is not increasing at row {k} (t = {tr.t[k - 1]:.6g} -> {tr.t[k]:.6g} s)")
        step = 1.0 / self.rate_hz
        worst = int(np.argmax(np.abs(dt - step)))
        if abs(dt[worst] - step) > RATE_RTOL * step:
            raise DatasetError(f"{label}: time stamps do not match rate_hz = {self.rate_hz:g} "
                               f"(step at row {worst + 1} is {dt[worst]:.6g} s = {1.0 / dt[worst]:.6g} Hz, "
                               f"median {1.0 / np.median(dt):.6g} Hz)")

    def for_robot(self, robot, where: str = "dataset") -> "Dataset":
        """This dataset with its columns in ``robot.joint_names`` order; unknown or missing joints are an error.
        A different robot-file hash only warns: the same robot may be saved under other bytes."""
        names = list(robot.joint_names)
        unknown = [n for n in self.joint_names if n not in names]
        missing = [n for n in names if n not in self.joint_names]
        if unknown:
            raise DatasetError(f"{where}: joint(s) {unknown} are not joints of {robot.source.name}")
        if missing:
            raise DatasetError(f"{where}: joint(s) {missing} of {robot.source.name} are missing")
        if robot.source_sha256 != self.robot_sha256:
            warnings.warn(f"{where}: recorded on a robot file with another hash ({self.robot_file}); "
                          f"using {robot.source}", stacklevel=3)
        if names == self.joint_names:
            return self
        cols = [self.joint_names.index(n) for n in names]
        trajs = [Trajectory(tr.name, tr.split, tr.t, tr.q[:, cols], tr.qd[:, cols], tr.qdd[:, cols], tr.q_cmd[:, cols],
                            None if tr.tau is None else tr.tau[:, cols]) for tr in self.trajectories]
        return Dataset(names, self.rate_hz, trajs, self.robot_file, self.robot_sha256, self.mismatch, self.seed,
                       self.meta, self.gains)

    def save(self, path) -> None:
        """Validate, then write atomically: a temporary file in the target folder, renamed over ``path``.
        On any error nothing is left behind and an existing file at ``path`` is untouched."""
        path = Path(path)
        self.validate(str(path))
        if not path.parent.is_dir():
            raise DatasetError(f"{path}: folder {path.parent} does not exist")
        entries, arrays = [], {}
        for i, tr in enumerate(self.trajectories):
            key = f"traj/{i:04d}"
            # q̈ that is exactly the documented derivative of q̇ is not stored: it is re-derived on load
            derived = np.array_equal(tr.qdd, derive_qdd(tr.qd, self.rate_hz))
            entries.append({"name": tr.name, "split": tr.split, "key": key, "n_samples": tr.n_samples,
                            "has_tau": tr.tau is not None, "qdd_derived": derived})
            for name in _FIELDS:
                a = getattr(tr, name)
                if a is not None and not (name == "qdd" and derived):
                    a32 = a.astype(np.float32)
                    arrays[f"{key}/{name}"] = a32 if np.array_equal(a32.astype(np.float64), a) else a
        header = {"format": FORMAT, "schema_version": SCHEMA_VERSION, "joint_names": list(self.joint_names),
                  "rate_hz": float(self.rate_hz), "units": UNITS, "robot_file": str(self.robot_file),
                  "robot_sha256": self.robot_sha256, "mismatch": self.mismatch, "seed": self.seed,
                  "meta": self.meta, "trajectories": entries}
        if self.gains is not None:  # absent otherwise: a file without gains is byte-identical to older wresdyn's
            header["gains"] = self.gains
        try:
            text = json.dumps(header, default=_jsonable, indent=1)
        except (TypeError, ValueError) as e:
            raise DatasetError(f"{path}: header is not JSON-serialisable: {e}") from None
        arrays["header"] = np.frombuffer(text.encode("utf-8"), dtype=np.uint8)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            os.chmod(tmp, 0o666 & ~_umask())  # mkstemp makes the file private; give it a normal file's mode
            with os.fdopen(fd, "wb") as f:
                np.savez_compressed(f, **arrays)
                f.flush()
                os.fsync(f.fileno())
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise

    @classmethod
    def load(cls, path, robot=None) -> "Dataset":
        """Read and validate a dataset file; with a :class:`~wresdyn.robot.description.Robot`, also map its joints by name
        into the robot's order (see :meth:`for_robot`)."""
        path = Path(path)
        if not path.is_file():
            raise DatasetError(f"{path}: dataset file not found")
        try:
            with np.load(path, allow_pickle=False) as z:
                files = {k: z[k] for k in z.files}
        except (zipfile.BadZipFile, OSError, ValueError, EOFError) as e:
            raise DatasetError(f"{path}: not a wresdyn dataset (.npz) file: {npz_failure(e)}") from None
        h = header_from(files, path)
        splits = READ_VERSIONS[h["schema_version"]]
        trajs = []
        for i, e in enumerate(h["trajectories"]):
            if not isinstance(e, dict) or not {"name", "split", "key"} <= set(e):
                raise DatasetError(f"{path}: trajectory entry {i} needs name, split and key")
            if e["split"] in SPLITS and e["split"] not in splits:  # other unknown splits: validate() below
                raise DatasetError(f"{path}: trajectory {e['name']!r} has split {e['split']!r}, which schema "
                                   f"version {h['schema_version']} does not have ({splits})")
            arr = {}
            for name in _FIELDS:
                a = files.get(f"{e['key']}/{name}")
                if name == "qdd" and e.get("qdd_derived") is True:
                    continue
                if a is None and name != "tau":
                    raise DatasetError(f"{path}: trajectory {e['name']!r} has no {name} array ({e['key']}/{name})")
                if a is not None and a.dtype.kind != "f":
                    raise DatasetError(f"{path}: trajectory {e['name']!r}: {name} is {a.dtype}, not floating point")
                arr[name] = a
            if e.get("qdd_derived") is True:
                qd = arr["qd"]
                if qd.ndim != 2 or not np.isfinite(qd).all() or not h["rate_hz"] > 0:
                    arr["qdd"] = np.full(qd.shape, np.nan)  # validate() reports the cause
                else:
                    arr["qdd"] = derive_qdd(qd, h["rate_hz"])
            trajs.append(Trajectory(e["name"], e["split"], **arr))
        ds = cls(h["joint_names"], h["rate_hz"], trajs, h["robot_file"], h["robot_sha256"], h["mismatch"],
                 h["seed"], h["meta"], h["gains"])
        ds.validate(str(path))
        return ds.for_robot(robot, str(path)) if robot is not None else ds


def load_dataset(path, robot=None) -> Dataset:
    """Read and validate a dataset file (see :meth:`Dataset.load`)."""
    return Dataset.load(path, robot)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _jsonable(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"{type(o).__name__} {o!r} is not JSON-serialisable")


def fitted_mask(weights, n_dof: int) -> np.ndarray:
    """The joints the metrics average over, bool (n_dof,): ``weights > 0`` for per-joint weights (n_dof,) such as
    :meth:`Dataset.fit_weights` (1 fitted, 0 excluded), every joint for ``None``."""
    if weights is None:
        return np.ones(n_dof, dtype=bool)
    w = np.asarray(weights, dtype=np.float64)
    if w.shape != (n_dof,) or not np.isfinite(w).all() or (w < 0).any():
        raise WresdynError(f"joint weights must be {n_dof} finite numbers >= 0 (one per joint), got shape {w.shape}")
    if not (w > 0).any():
        raise WresdynError("joint weights exclude every joint: no joint left to measure")
    return w > 0
