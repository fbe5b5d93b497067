"""What the online identifier does after a change of the robot: a detector of a jump in the current model's held-back
error (:class:`ChangeDetector`) that opens a tracking mode, and a grid of lower effort limits for a joint whose own
error jumped (:func:`search_effort`).

A change shows as a jump of the current model's held-back open-loop error above its recent level; the motion alone
makes that error vary from second to second (up to 1.5x its median without drift on the drift benchmark's validation
timeline), so the jump is measured against the median of the last
:attr:`~wresdyn.adapt.config.AdaptConfig.detect_history` seconds of updates and must exceed
:attr:`~wresdyn.adapt.config.AdaptConfig.detect_factor` times it. The same test per joint (each joint's own held-back
error against its own median) flags the joints whose error jumped: where such a joint's PD drive asks for more torque
than a lower limit would give, the limit is a suspect. An effort limit above every torque the motion asks for has no
gradient (the simulated drive never saturates), so, as offline identification's grid search, lower limits are tried
by replay instead: picked on the held-back part that showed the jump, kept only if they win again on the next one.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..sim import rollout
from ..sim.fused import fused_rollout

__all__ = ["NORM_FLOOR", "ChangeDetector", "command_rate", "demanded_torque", "effort_candidates", "replay_limits",
           "search_effort"]


NORM_FLOOR = 0.25
"""With :attr:`ChangeDetector.norm`, a held-back part's motion counts as at least this times the recent median: a robot
coming to rest (a command that hardly moves) would otherwise blow its error up."""


def command_rate(q_cmd: np.ndarray) -> float:
    """How fast a command moves: the RMS over samples and joints of its change from one sample to the next [rad],
    ``q_cmd`` (T, n) [rad]."""
    d = np.diff(np.asarray(q_cmd, dtype=np.float64), axis=0)
    return float(np.sqrt(np.mean(d ** 2))) if d.size else 0.0


class ChangeDetector:
    """Running medians of the held-back errors and the tracking mode they open.

    Args:
        factor: A jump is an error above ``factor`` times the median of the recent ones.
        history: How many earlier updates the median is taken over (at least 3 are needed before anything fires).
        track_for: Robot time the tracking mode lasts after a jump [s].
        confirm: Consecutive updates whose error must jump before the tracking mode opens (1: the first jump opens
            it); a change persists, a swing of the motion often lasts one held-back part.
        overall: A joint's own jump counts for the effort grid only where the overall error is above ``overall``
            times its median too (0: always).
        norm: Divide each held-back error by the held-back part's motion (``scale`` of :meth:`observe`), at least
            :data:`NORM_FLOOR` times the recent ones' median, before comparing it with the recent ones: a swing of the
            motion moves the error and the motion together, a change of the robot the error alone.
    """

    def __init__(self, factor: float, history: int, track_for: float, confirm: int = 1, overall: float = 0.0,
                 norm: bool = False) -> None:
        self.factor, self.track_for, self.confirm = float(factor), float(track_for), max(1, int(confirm))
        self.overall, self.norm = float(overall), bool(norm)
        self.scales: deque[float] = deque(maxlen=max(3, int(history)))
        """The motion of each recent update's held-back part (with ``norm``)."""
        self.streak = 0
        """Consecutive updates, up to the last, whose error jumped."""
        self.streak_from = -np.inf
        """Robot time the held-back part of the streak's first jump starts [s]."""
        self.joint_streak: np.ndarray | int = 0
        """Consecutive updates, up to the last, whose error jumped, per joint ((n,) after the first comparison)."""
        self.errors: deque[float] = deque(maxlen=max(3, int(history)))
        """Held-back error of the model before each recent update [rad]."""
        self.joints: deque[np.ndarray] = deque(maxlen=max(3, int(history)))
        """The same per joint, (n,) each [rad]."""
        self.until = -np.inf
        """Robot time the tracking mode ends [s]."""
        self.since = -np.inf
        """Robot time from which the window holds data after the last jump [s]."""
        self.joint_ratios: np.ndarray | None = None
        """Each joint's held-back error over its recent median at the last update, (n,) (``None`` before one); 0
        where the joint's jump is not yet the ``confirm``-th in a row, and everywhere while the overall error is not
        above ``overall`` times its median."""

    def ratios(self, error: float, joints: np.ndarray) -> tuple[float, np.ndarray]:
        """``error`` [rad] and ``joints`` (n,) [rad] over the medians of the earlier ones (0 while fewer than 3)."""
        if len(self.errors) < 3:
            return 0.0, np.zeros_like(joints)
        med = float(np.median(self.errors))
        jmed = np.median(np.stack(self.joints), 0)
        # 1e-12 rad: only a joint that never moved has a median this small; it keeps the division finite
        return error / max(med, 1e-12), joints / np.maximum(jmed, 1e-12)

    def observe(self, t: float, t_holdout: float, error: float, joints: np.ndarray, scale: float = 1.0
                ) -> tuple[bool, float, np.ndarray]:
        """Take the current model's held-back error of the update at robot time ``t`` [s] (its held-back part starts
        at ``t_holdout``): ``error`` [rad] overall and ``joints`` (n,) [rad] per joint; with ``norm`` both divided by
        the held-back part's motion ``scale`` (:func:`command_rate`). Returns (whether it jumped, the ratio to the
        median, the per-joint ratios). A jump (the ``confirm``-th in a row) outside the tracking mode opens it and
        marks the held-back start of the streak's first jump as the start of the data after the change."""
        if self.norm:
            floor = NORM_FLOOR * float(np.median(self.scales)) if self.scales else 0.0
            self.scales.append(float(scale))
            scale = max(float(scale), floor, 1e-12)
            error, joints = error / scale, np.asarray(joints) / scale
        ratio, jratio = self.ratios(error, joints)
        self.streak = self.streak + 1 if ratio > self.factor else 0
        if self.streak == 1:
            self.streak_from = t_holdout
        jumped = self.streak >= self.confirm
        if jumped and not self.tracking(t):
            self.since = self.streak_from
        if jumped:
            self.until = t + self.track_for
        if len(self.errors) < 3:
            self.joint_ratios = None
        else:  # a joint's own jump counts for the effort grid once it too is the confirm-th in a row
            self.joint_streak = np.where(jratio > self.factor, self.joint_streak + 1, 0)
            self.joint_ratios = np.where((self.joint_streak >= self.confirm) & (ratio > self.overall), jratio, 0.0)
        self.errors.append(float(error))
        self.joints.append(np.asarray(joints, dtype=np.float64).copy())
        return bool(jumped), ratio, jratio

    def tracking(self, t: float) -> bool:
        """Whether robot time ``t`` [s] is within the tracking mode."""
        return t <= self.until + 1e-9  # robot times are sums of sample periods: equal up to rounding


def demanded_torque(kp: np.ndarray, kd: np.ndarray, q: np.ndarray, qd: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The largest torque each PD drive asks for over a recording, max_k |kp (target_k − q_k) − kd q̇_k| [N·m], (n,):
    ``kp`` [N·m/rad], ``kd`` [N·m·s/rad] (n,); ``q`` [rad], ``qd`` [rad/s], ``target`` (the delayed command) [rad],
    each (T, n)."""
    return np.abs(kp * (target - q) - kd * qd).max(0)


def effort_candidates(physics, joints, demand: np.ndarray, grid) -> list[tuple[int, float]]:
    """(joint, limit [N·m]) pairs to try: for each of ``joints``, each factor of ``grid`` times the model's current
    limit (``physics.effort``) that lies below the joint's ``demand`` (n,) [N·m], the torque its drive asked for (a
    limit above it changes nothing)."""
    out = []
    for j in joints:
        for g in grid:
            limit = float(g * physics.effort[j])
            if np.isfinite(limit) and limit < demand[j]:
                out.append((int(j), limit))
    return out


def replay_limits(sim, window, physics, candidates, fused: bool) -> tuple[list, np.ndarray]:
    """Replay ``physics`` with each (joint, limit [N·m]) of ``candidates`` open loop on ``window`` (one held-back
    segment, :class:`~wresdyn.sim.bank.Window` of B = 1), one world of ``sim`` each (``sim`` has at least as many
    worlds; the spare ones replay the last candidate again); ``fused``: in one launch
    (:func:`~wresdyn.sim.fused.fused_rollout`). Returns the candidate models and their errors per joint, mean
    |q_sim − q| [rad], (len(candidates), n)."""
    import torch

    models = []
    for j, limit in candidates:
        m = physics.copy()
        m.effort[j] = limit
        models.append(m)
    for w in range(sim.num_worlds):
        sim.set_physics(models[min(w, len(models) - 1)], worlds=slice(w, w + 1))
    window = window.repeat(sim.num_worlds)
    with torch.no_grad():
        q = fused_rollout(sim, window)[0] if fused else rollout(sim, window).q
    err = (q[:, 1:] - window.q[:, 1:]).abs().mean(1).cpu().numpy()[:len(models)]
    return models, np.nan_to_num(err.astype(np.float64), nan=np.inf)  # a diverged replay never wins


def search_effort(sim_grid, sim_val, select, holdout, physics, joint_jump: np.ndarray, cfg, error: float,
                  fused: bool):
    """The effort grid of the tracking mode: lower limits (:func:`effort_candidates`, ``cfg.effort_grid``) on the
    joints whose held-back error jumped most (at most ``cfg.effort_joints``, each ``joint_jump`` above
    ``cfg.detect_factor``), replayed on ``select`` (a :class:`~wresdyn.sim.bank.Window` of B = 1, the held-back part
    that showed the jump; ``sim_grid`` has a world for each and one more). The one that lowers its joint's error most there, by
    ``cfg.min_gain`` at least, wins if on ``holdout`` (``sim_val``, two worlds or more), which it was not picked on,
    it lowers that joint's error by ``cfg.min_gain`` again and the mean over joints, ``error`` [rad] with
    ``physics``, not at all: the joint's error is what a limit explains; the mean guards the others.

    Returns (limits tried, ``(joint, limit [N·m], the model with it)`` or ``None``, the held-back error after [rad]).
    """
    gain = 1.0 - cfg.min_gain
    order = [int(j) for j in np.argsort(-joint_jump) if joint_jump[j] > cfg.detect_factor][:cfg.effort_joints]
    p = physics
    demand = demanded_torque(p.kp, p.kd, *(a[0, :-1].cpu().numpy() for a in (select.q, select.qd)),
                             select.target[0].cpu().numpy())
    cands = effort_candidates(p, order, demand, cfg.effort_grid)
    if not cands:
        return 0, None, error
    # the model itself last (its own limit): the reference
    models, err = replay_limits(sim_grid, select, p, [*cands, (cands[0][0], p.effort[cands[0][0]])], fused)
    rel = np.array([err[k, j] / max(err[-1, j], 1e-12) for k, (j, _) in enumerate(cands)])
    best = int(np.argmin(rel))
    if not rel[best] < gain:
        return len(cands), None, error
    j, limit = cands[best]
    _, again = replay_limits(sim_val, holdout, p, [cands[best], (j, p.effort[j])], fused)
    if not (again[0, j] < gain * again[1, j] and again[0].mean() <= error):
        return len(cands), None, error
    return len(cands), (j, limit, models[best]), float(again[0].mean())
