"""A log brought onto the simulation step t_k = k / rate_hz (:func:`resample`): measured positions, velocities and
torques interpolated linearly, commands held (zero-order hold on their own stamps), q̈ derived from the resampled q̇;
one log as a dataset :class:`~wresdyn.data.dataset.Trajectory` (:func:`to_trajectory`) and its sampling statistics
(:func:`log_stats`). The logs themselves are read by :mod:`wresdyn.data.log_files`."""

from __future__ import annotations

import numpy as np

from .dataset import SPLITS, DatasetError, Trajectory, derive_qdd

__all__ = ["resample", "log_stats", "to_trajectory"]

_ZOH_EPS = 1e-6
"""A grid time within this fraction of a step after a logged command time counts as at or after it, so
float rounding of k / rate never holds the previous command one log sample too long."""


def resample(log: dict, rate_hz: float) -> dict[str, np.ndarray | None]:
    """Bring a log onto t_k = k / rate_hz: linear interpolation of measured q, q̇ and τ, zero-order hold of q_cmd
    on its own stamps (``log["t_cmd"]``, default the state stamps ``log["t"]``). k = 0 is the first state stamp at
    which a command is in force (the first state stamp when commands start with the states). Without a logged q̇
    it is the derivative of q (second-order differences on the log's own time stamps), interpolated the same way.
    Returns the :func:`~wresdyn.data.logs.read_log` keys (``t`` starting at 0, no ``t_cmd``) plus ``qdd``."""
    t_cmd = log.get("t_cmd")
    t_cmd = log["t"] if t_cmd is None else t_cmd
    t0 = max(log["t"][0], t_cmd[0])
    t_log, tc_log = log["t"] - t0, t_cmd - t0
    if not t_log[-1] > 0:
        raise DatasetError("log has no state time stamp after its first command")
    t = np.arange(int(np.floor(t_log[-1] * rate_hz + _ZOH_EPS)) + 1) / rate_hz
    qd_log = log["qd"] if log["qd"] is not None else np.gradient(log["q"], t_log, axis=0)

    def lerp(a):
        return None if a is None else np.stack([np.interp(t, t_log, a[:, j]) for j in range(a.shape[1])], axis=1)

    held = np.searchsorted(tc_log, t + _ZOH_EPS / rate_hz, side="right") - 1
    qd = lerp(qd_log)
    return {"t": t, "q": lerp(log["q"]), "qd": qd, "qdd": derive_qdd(qd, rate_hz), "q_cmd": log["q_cmd"][held],
            "tau": lerp(log["tau"])}


def log_stats(t: np.ndarray) -> dict:
    """Sampling of a log's state stamps ``t`` (N,) [s]: ``samples``, ``duration_s``, ``median_rate_hz``,
    ``jitter`` (std of the step / median step) and ``max_gap_s`` (longest step)."""
    dt = np.diff(t)
    med = float(np.median(dt))
    return {"samples": len(t), "duration_s": float(t[-1] - t[0]), "median_rate_hz": 1.0 / med,
            "jitter": float(dt.std() / med), "max_gap_s": float(dt.max())}


def to_trajectory(log: dict, rate_hz: float, name: str, split: str, where: str, store_tau: bool = True) -> Trajectory:
    """Resample one :func:`~wresdyn.data.logs.read_log` dict onto the grid as a
    :class:`~wresdyn.data.dataset.Trajectory`."""
    if split not in SPLITS:
        raise DatasetError(f"{where}: unknown split {split!r}; choose from {SPLITS}")
    t_cmd = log.get("t_cmd")
    t0 = log["t"][0] if t_cmd is None else max(log["t"][0], t_cmd[0])
    if (log["t"][-1] - t0) * rate_hz < 1:
        raise DatasetError(f"{where}: log is shorter than one simulation step")
    r = resample(log, rate_hz)
    return Trajectory(name, split, r["t"], r["q"], r["qd"], r["qdd"], r["q_cmd"], r["tau"] if store_tau else None)
