"""Reference motions of the skills: keyframes of the soles (solved by the foot IK) and of the arm joints.

No mocap: every motion is drawn from a family of keyframe sequences, the leg joints from the sole IK of
:mod:`wresdyn.data.ik` (Pinocchio; the excitation's machinery), the arm and waist joints from joint-space
keyframes by name pattern, minimum-jerk between keyframes (zero speed at each). Families:

- ``kick``: one sole is pulled back and up, thrust forward and up, and returned;
- ``squat``: both soles rise together (the legs fold, as a squat does relative to the pelvis), once or twice;
- ``wave``: one arm is raised sideways and the forearm waves once or twice, the legs hold the stance;
- ``march`` (held out from training by default): the soles lift in turn, knee up, two steps each.

Each drawn motion varies its amplitudes, side and tempo (seeded). A motion starts and ends at rest in the
neutral stance (:data:`STANCE`), the start state of every episode in :mod:`wresdyn.skills.env`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..data.ik import FootIK
from ..robot.description import Robot, RobotError

__all__ = ["FAMILIES", "TRAIN_FAMILIES", "HELD_OUT_FAMILIES", "STANCE", "Motion", "MotionSet", "make_motions",
           "stance"]

FAMILIES = ("kick", "squat", "wave", "march")
"""Motion families."""
TRAIN_FAMILIES = ("kick", "squat", "wave")
"""Families the skill policies train on (other draws of them are the validation and held-out motions)."""
HELD_OUT_FAMILIES = ("march",)
"""The family no policy trains on: held-out motions of an unseen kind."""
STANCE = {"hip_pitch": -0.3, "knee": 0.6, "ankle_pitch": -0.3}
"""Neutral stance [rad] by joint-name suffix (knees slightly bent); every other joint 0."""


@dataclass
class Motion:
    """One reference motion."""

    name: str
    family: str
    q: np.ndarray
    """Reference joint positions [rad], shape (T, n_dof), sample k at t = k / rate_hz."""
    qd: np.ndarray
    """Reference joint velocities [rad/s], shape (T, n_dof) (central differences)."""
    feet: np.ndarray
    """Reference sole positions in the base frame [m], shape (T, n_feet, 3) (forward kinematics of ``q``)."""
    params: dict = field(default_factory=dict)


@dataclass
class MotionSet:
    """Motions of one robot at one rate, by split (``train``, ``validation``, ``heldout``)."""

    rate_hz: float
    splits: dict[str, list[Motion]]

    def split(self, name: str) -> list[Motion]:
        return self.splits.get(name, [])


def stance(robot: Robot) -> np.ndarray:
    """The neutral stance [rad], shape (n_dof,): :data:`STANCE` by joint-name suffix, clipped into the limits."""
    q = np.zeros(robot.n_dof)
    for i, name in enumerate(robot.joint_names):
        for suffix, v in STANCE.items():
            if name.endswith(suffix):
                q[i] = v
    return np.clip(q, robot.lower, robot.upper)


def _min_jerk(s):
    return 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5


def _keyframes(t: np.ndarray, times, values) -> np.ndarray:
    """Minimum-jerk interpolation through keyframes ``values[i]`` at ``times[i]`` (held outside); shape (T, ...)."""
    values = np.asarray(values, dtype=np.float64)
    out = np.broadcast_to(values[0], (len(t),) + values.shape[1:]).copy()
    for i in range(1, len(times)):
        s = np.clip((t - times[i - 1]) / (times[i] - times[i - 1]), 0.0, 1.0)
        w = _min_jerk(s).reshape((-1,) + (1,) * (values.ndim - 1))
        sel = t >= times[i - 1]
        out[sel] = (values[i - 1] + w * (values[i] - values[i - 1]))[sel]
    return out


def _joint(robot: Robot, name: str) -> int:
    return list(robot.joint_names).index(name)


def _leg_keys(rng, family: str, home: np.ndarray, duration: float):
    """Sole keyframes (times [s], positions (K, 2, 3) [m]) of a leg family; ``home`` (2, 3) the stance soles."""
    up, fwd = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    if family == "kick":
        f = int(rng.integers(2))
        back, out_x, out_z = rng.uniform(0.03, 0.06), rng.uniform(0.10, 0.17), rng.uniform(0.06, 0.11)
        t1, t2, t3 = np.sort(rng.uniform([0.2, 0.45, 0.7], [0.35, 0.6, 0.85])) * duration
        k1, k2 = home.copy(), home.copy()
        k1[f] += -back * fwd + 0.6 * out_z * up
        k2[f] += out_x * fwd + out_z * up
        return [0.0, t1, t2, t3, duration], [home, k1, k2, home, home], {"foot": f, "forward_m": out_x, "up_m": out_z}
    if family == "squat":
        reps = int(rng.integers(1, 3))
        depth, lean = rng.uniform(0.05, 0.11), rng.uniform(-0.02, 0.03)
        low = home + depth * up + lean * fwd
        times, keys = [0.0], [home]
        span = 0.85 * duration / reps
        for r in range(reps):
            times += [0.1 * duration + r * span + 0.5 * span, 0.1 * duration + (r + 1) * span]
            keys += [low, home]
        return times + [duration], keys + [home], {"reps": reps, "depth_m": depth}
    if family == "march":
        lift, step = rng.uniform(0.05, 0.10), rng.uniform(0.0, 0.05)
        times, keys, t0 = [0.0], [home], 0.08 * duration
        seg = 0.88 * duration / 4
        first = int(rng.integers(2))
        for i in range(4):
            f = (first + i) % 2
            k = home.copy()
            k[f] += lift * up + step * fwd
            times += [t0 + (i + 0.5) * seg, t0 + (i + 1) * seg]
            keys += [k, home]
        return times + [duration], keys + [home], {"lift_m": lift, "first_foot": first}
    return [0.0, duration], [home, home], {}


def _arm_keys(rng, robot: Robot, family: str, duration: float, side: str | None = None):
    """Arm joint offsets from the stance, (T-independent keyframes): times [s], values (K, n_dof) [rad].

    ``side``: the waving arm (``"left"``/``"right"``); ``None`` draws it. The draw is made either way, so the other
    amplitudes do not depend on whether the side was given.
    """
    n = robot.n_dof
    if family != "wave":
        return [0.0, duration], [np.zeros(n), np.zeros(n)], {}
    drawn = ("left", "right")[int(rng.integers(2))]
    side = drawn if side is None else side
    sign = 1.0 if side == "left" else -1.0
    names = list(robot.joint_names)
    roll, elbow = f"{side}_shoulder_roll", f"{side}_elbow"
    if roll not in names or elbow not in names:
        raise RobotError(f"{robot.source}: the wave needs joints named {roll!r} and {elbow!r}")
    raise_ = rng.uniform(0.8, 1.3)
    bend, amp = rng.uniform(-1.3, -0.9), rng.uniform(0.25, 0.4)
    waves = int(rng.integers(1, 3))
    up = np.zeros(n)
    up[_joint(robot, roll)] = sign * raise_
    up[_joint(robot, elbow)] = bend
    times, keys = [0.0, 0.3 * duration], [np.zeros(n), up]
    seg = 0.4 * duration / (2 * waves)
    for i in range(2 * waves):
        k = up.copy()
        k[_joint(robot, elbow)] = bend + (amp if i % 2 == 0 else -amp)
        times.append(0.3 * duration + (i + 1) * seg)
        keys.append(k)
    times += [0.95 * duration, duration]
    keys += [np.zeros(n), np.zeros(n)]
    home = stance(robot)
    keys = [np.clip(k, robot.lower - home, robot.upper - home) for k in keys]
    return times, keys, {"arm": side, "raise_rad": raise_, "waves": waves}


def make_motion(robot: Robot, ik: FootIK, family: str, duration: float, rate_hz: float, rng: np.random.Generator,
                name: str, ik_tol: float = 0.005, max_draws: int = 20, side: str | None = None) -> Motion:
    """Draw one motion of ``family`` (redrawn until the sole IK reaches every keyframe path within ``ik_tol`` [m]);
    ``side`` fixes a wave's arm (default: drawn)."""
    if family not in FAMILIES:
        raise ValueError(f"unknown motion family {family!r}; choose from {FAMILIES}")
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    q0 = stance(robot)
    home, rot = ik.forward(q0)
    rots = np.broadcast_to(rot, (len(t),) + rot.shape)
    for _ in range(max_draws):
        lt, lk, lp = _leg_keys(rng, family, home, duration)
        at, ak, ap = _arm_keys(rng, robot, family, duration, side)
        pos = _keyframes(t, lt, lk)
        q, err = ik.solve_path(pos, None if ik.position_only else rots, q0)
        if float(err[:, :, 0].max()) > ik_tol:
            continue
        q = q + _keyframes(t, at, ak)
        q = np.clip(q, robot.lower, robot.upper)
        qd = np.gradient(q, 1.0 / rate_hz, axis=0)
        feet = np.array([ik.forward(x)[0] for x in q])
        return Motion(name, family, q, qd, feet, {**lp, **ap, "ik_max_error_m": float(err[:, :, 0].max())})
    raise RobotError(f"{robot.source}: no {family} motion reached its sole keyframes within {ik_tol} m in "
                     f"{max_draws} draws")


def make_motions(robot: Robot, counts: dict[str, int], duration: float = 2.0, rate_hz: float = 500.0, seed: int = 0,
                 frames=None) -> MotionSet:
    """Draw the motion set: ``counts`` maps a split to motions per family (training families for ``train`` and
    ``validation``; ``heldout`` draws new motions of the training families and of :data:`HELD_OUT_FAMILIES`).

    Args:
        robot: Fixed-base robot with sole frames (``frames``, default the IK's ``left_sole``/``right_sole``).
        counts: Motions per family and split, e.g. ``{"train": 4, "validation": 1, "heldout": 2}``.
        duration: Length of each motion [s].
        rate_hz: Sample rate [Hz] (the simulation's).
        seed: Seed of the draws; each split draws from its own stream.

    The waves of a split alternate between the arms (the first arm drawn per split), so a split of two or more waves
    has both: training on one arm's waves alone leaves a policy untaught for the other's.
    """
    if robot.base != "fixed":
        raise RobotError(f"{robot.source}: the skill motions are drawn on the stand (a fixed base)")
    ik = FootIK(robot) if frames is None else FootIK(robot, tuple(frames))
    splits = {}
    for s, (split, per) in enumerate(counts.items()):
        rng = np.random.default_rng([seed, s])
        first = int(np.random.default_rng([seed, s, 1]).integers(2))
        fams = TRAIN_FAMILIES + (HELD_OUT_FAMILIES if split == "heldout" else ())
        splits[split] = [make_motion(robot, ik, f, duration, rate_hz, rng, f"{split}_{f}_{i}",
                                     side=("left", "right")[(first + i) % 2] if f == "wave" else None)
                         for f in fams for i in range(per)]
    return MotionSet(float(rate_hz), splits)
