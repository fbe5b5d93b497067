"""Joint-space excitation: commands drawn per joint for robots where IK targets make no sense (an arm).

``multisine`` for train, validation and held-out, ``chirp`` and ``steps`` (minimum-jerk moves between random
joint positions) out of distribution (:data:`~wresdyn.data.signals.JOINT_FAMILIES`). Each joint stays inside
its limits, its command speed under ``joint_max_velocity``, and the torque the command needs (inverse dynamics
of the nominal robot: inertia and armature, gravity, damping and friction) under ``effort_fraction`` of its
effort limit. :func:`wresdyn.data.excitation.plan` selects this mode; the foot-space families live in
:mod:`wresdyn.data.excitation`.
"""

from __future__ import annotations

import numpy as np

from ..robot.description import Robot, RobotError
from ..robot.pinocchio_model import build_pinocchio
from .signals import (
    JOINT_FAMILIES,
    Excitation,
    ExcitationConfig,
    centre_amplitude,
    chirp,
    fade,
    finite_limits,
    limit_margin,
    min_jerk,
)

__all__ = ["JointDynamics", "effort_limit", "generate_joint"]


class JointDynamics:
    """Inverse dynamics of the nominal robot (Pinocchio RNEA, armature included) plus its joint damping and
    dry friction: the torque a command needs if the robot followed it exactly."""

    def __init__(self, robot: Robot):
        import pinocchio as pin

        self.robot, self._pin = robot, pin
        self.model = build_pinocchio(robot)
        self.data = self.model.createData()

    def torque(self, q: np.ndarray, rate_hz: float) -> np.ndarray:
        """Torque [N*m] to follow ``q`` [rad], shape (T, n_dof): q̇ and q̈ by central differences."""
        dt = 1.0 / rate_hz
        qd = np.gradient(q, dt, axis=0)
        qdd = np.gradient(qd, dt, axis=0)
        r = self.robot
        tau = np.array([self._pin.rnea(self.model, self.data, q[k], qd[k], qdd[k]) for k in range(len(q))])
        return tau + r.damping * qd + r.friction * np.sign(qd)

    def accel_budget(self, q: np.ndarray, limit: np.ndarray) -> np.ndarray:
        """Acceleration each joint can have alone at ``q`` with ``limit`` torque [N*m] left after gravity
        [rad/s^2], shape (n_dof,): (limit - |g(q)|) / M_jj(q), at least 0 (inf where the limit is)."""
        pin = self._pin
        g = pin.computeGeneralizedGravity(self.model, self.data, q)
        m = np.diag(pin.crba(self.model, self.data, q))
        with np.errstate(invalid="ignore"):
            return np.where(np.isfinite(limit), np.maximum(limit - np.abs(g) - self.robot.friction, 0.0) / m, np.inf)


def effort_limit(robot: Robot, cfg: ExcitationConfig) -> np.ndarray:
    """Torque a joint-space command may need [N*m], shape (n_dof,): ``effort_fraction`` of the effort limit (inf
    where there is none)."""
    return np.where(np.isfinite(robot.effort), cfg.effort_fraction * robot.effort, np.inf)


def _joint_multisine(rng, robot: Robot, t, cfg, rate_hz, amax) -> tuple[np.ndarray, dict]:
    """A multisine per joint about a random centre inside its limits (as the foot mode's upper body, amplitudes
    ∝ f^-slope summing to the excursion), each sine's amplitude capped to 1/n_sines of the speed
    (``joint_max_velocity``) and acceleration (``amax`` [rad/s^2]) budgets, then each joint's oscillation scaled
    down if the fade-in still exceeds them; shape (T, n_dof)."""
    lo, hi = finite_limits(robot)
    q, params = np.empty((len(t), robot.n_dof)), {}
    n = cfg.n_sines
    for j in range(robot.n_dof):
        c, amp = centre_amplitude(rng, lo[j], hi[j], cfg)
        f = np.exp(rng.uniform(np.log(cfg.band[0]), np.log(cfg.band[1]), size=n))
        a = f ** -cfg.slope
        a *= amp / a.sum()
        # each sine keeps 1/n of the speed and acceleration budgets: high frequencies get small amplitudes,
        # low ones keep theirs
        w = 2 * np.pi * f
        a = np.minimum(a, np.minimum(cfg.joint_max_velocity / (n * w), amax[j] / (n * w ** 2)))
        ph = rng.uniform(0.0, 2 * np.pi, size=n)
        s = fade(t, cfg) * (a[:, None] * np.sin(w[:, None] * t + ph[:, None])).sum(axis=0)
        p = {"f": f.tolist(), "a": a.tolist(), "phase": ph.tolist()}
        speed = np.abs(np.diff(s)).max() * rate_hz
        acc = np.abs(np.diff(s, 2)).max() * rate_hz ** 2
        scale = min(1.0, 0.95 * cfg.joint_max_velocity / max(speed, 1e-12), 0.95 * amax[j] / max(acc, 1e-12))
        q[:, j] = c + scale * s
        params[robot.joint_names[j]] = {"centre": c, "scale": scale, **p}
    return q, params


def _joint_steps(rng, robot: Robot, t, cfg, amax) -> tuple[np.ndarray, dict]:
    """Every joint makes minimum-jerk moves between random positions inside its limits, with its own random
    durations (``kick_time``) and pauses; each move is shortened so that its peak speed (1.875 d / T) stays under
    ``joint_max_velocity`` and its peak acceleration (5.77 d / T^2) under ``amax``."""
    lo, hi = finite_limits(robot)
    q, moves = np.empty((len(t), robot.n_dof)), {}
    for j in range(robot.n_dof):
        m = limit_margin(lo[j], hi[j], cfg.limit_margin)
        a, b = lo[j] + m, hi[j] - m
        cur = rng.uniform(a, b) if b > a else 0.5 * (lo[j] + hi[j])
        q[:, j] = cur
        t0, js = rng.uniform(0.0, 0.3), []
        while t0 < t[-1] and b > a:
            dur = rng.uniform(*cfg.kick_time)
            goal = rng.uniform(a, b)
            reach = min(cfg.joint_max_velocity * dur / 1.875, amax[j] * dur ** 2 / 5.77) * 0.95
            goal = cur + np.clip(goal - cur, -reach, reach)
            s = np.clip((t - t0) / dur, 0.0, 1.0)
            q[:, j] = np.where(t >= t0, cur + min_jerk(s) * (goal - cur), q[:, j])
            js.append({"t0": t0, "duration": dur, "goal": goal})
            cur = goal
            t0 += dur + rng.uniform(0.0, 0.3)
        moves[robot.joint_names[j]] = js
    return q, {"moves": moves}


def generate_joint(family: str, robot: Robot, duration: float, rate_hz: float, rng: np.random.Generator,
                   cfg: ExcitationConfig | None = None, dynamics: JointDynamics | None = None) -> Excitation:
    """Draw one joint-space excitation of ``family`` (one of :data:`JOINT_FAMILIES`); redraws (same generator)
    until the limit, speed (``joint_max_velocity``) and effort (``effort_fraction``) checks pass.

    Args:
        family: ``"multisine"``, ``"chirp"`` or ``"steps"``.
        robot: The robot (fixed base).
        duration: Trajectory length [s].
        rate_hz: Command rate [Hz].
        rng: Random generator (advanced in place).
        cfg: Parameter ranges.
        dynamics: Inverse dynamics of ``robot`` (made here when ``None``; pass one to draw many).

    Raises:
        RobotError: no draw passed the checks in ``max_draws`` tries (one line naming the worst joint).
    """
    cfg = cfg or ExcitationConfig()
    if family not in JOINT_FAMILIES:
        raise ValueError(f"unknown joint-space excitation family {family!r}; choose from {JOINT_FAMILIES}")
    dyn = dynamics or JointDynamics(robot)
    t = np.arange(int(round(duration * rate_hz))) / rate_hz
    lo, hi = finite_limits(robot)
    margin = limit_margin(lo, hi, cfg.limit_margin)
    limit = effort_limit(robot, cfg)
    amax = dyn.accel_budget(np.clip(np.zeros(robot.n_dof), lo, hi), limit)
    amax = np.where(np.isfinite(amax), amax, 1e6)
    worst = (0.0, "")
    for draw in range(cfg.max_draws):
        if family == "multisine":
            q, params = _joint_multisine(rng, robot, t, cfg, rate_hz, amax)
        elif family == "chirp":
            q, params = chirp(rng, robot, t, cfg, cfg.joint_max_velocity, amax)
        else:
            q, params = _joint_steps(rng, robot, t, cfg, amax)
        speed = float(np.abs(np.diff(q, axis=0)).max() * rate_hz)
        inside = (q >= lo + 0.5 * margin).all() and (q <= hi - 0.5 * margin).all()
        tau = dyn.torque(q, rate_hz)
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(np.isfinite(limit), np.abs(tau).max(axis=0) / limit, 0.0)
        if ratio.max() > worst[0]:
            worst = (float(ratio.max()), robot.joint_names[int(np.argmax(ratio))])
        if speed <= cfg.joint_max_velocity and inside and ratio.max() <= 1.0:
            params.update(family=family, draws=draw + 1, max_speed=speed,
                          peak_effort_fraction=float(cfg.effort_fraction * ratio.max()))
            return Excitation(family=family, q_cmd=q, params=params)
        # the budget at the neutral pose was too generous for this draw's poses: tighten it
        amax = amax * 0.8
    raise RobotError(f"{robot.source}: no joint-space {family} excitation passed the limit, speed "
                     f"({cfg.joint_max_velocity} rad/s) and effort ({cfg.effort_fraction:g} of the limit) checks in "
                     f"{cfg.max_draws} draws (worst: {worst[1]} needs {worst[0] * cfg.effort_fraction:.2f} of its "
                     "effort limit); can it hold itself up against gravity?")
