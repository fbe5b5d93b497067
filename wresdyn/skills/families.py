"""The motion families of the skills, one registry for both tasks: which families each task trains on, holds out or
may add, and the keyframes each family draws (soles in the pelvis-fixed frame, arm joints as offsets from the stance).

No mocap: every motion is drawn from a family of keyframe sequences (:mod:`.motions` solves the soles' IK and plays
the keyframes minimum-jerk, zero speed at each). On the stand (:data:`TASK_FAMILIES` ``stand``):

- ``kick``: one sole is pulled back and up, thrust forward and up, and returned;
- ``squat``: both soles rise together (the legs fold, as a squat does relative to the pelvis), once or twice;
- ``wave``: one arm is raised sideways and the forearm waves once or twice, the legs hold the stance;
- ``march`` (held out): the soles lift in turn, knee up, two steps each.

On the floor (``floor``; motions that lift a foot first shift the weight over the other: ``shift[f]`` is the sideways
shift of both soles that puts the centre of mass above sole f):

- ``squat`` and ``wave``: as on the stand;
- ``weight_shift``: the centre of mass moves over one sole, then over the other, and back;
- ``kick``: weight onto one foot, the other sole pulled back and up, thrust forward and returned, weight back, each
  phase of its own drawn duration;
- ``step`` (held out): stepping in place: the weight over one foot, the other lifted (knee up, its own height and
  reach) and set down where it stood, once or twice, in longer motions sometimes then the weight across and the
  other foot lifted; every transfer and every phase of a lift of its own drawn duration;
- ``combo`` (an optional training family): compositions of the weight shifts' and kicks' keyframes, as many as fit
  the motion (up to three) in a random order with random durations: single-leg support on either foot, the weight
  carried straight across from one foot to the other, transfers slow enough to follow and too fast for any robot to
  follow (the floor would have to pull), where a policy must give up tracking to keep its balance. The lifted foot
  only ever kicks (back, then forward); it is never just lifted and set down.

Each drawn motion varies its amplitudes, side and tempo (seeded). On the floor a transfer of the weight takes about a
second at the least (:data:`FLOOR_TRANSFER_S`): faster, the zero-moment point leaves the soles, and the screening of
:func:`~.motions.make_motions` slows or redraws the motion.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot.description import Robot, RobotError

__all__ = ["MotionFamilies", "TASK_FAMILIES", "FAMILIES", "STANCE", "COMBO_TRANSFER_S", "FLOOR_TRANSFER_S",
           "FLOOR_ACROSS_S", "FLOOR_SWING_S", "stance", "leg_keys", "arm_keys", "keyframes"]


@dataclass(frozen=True)
class MotionFamilies:
    """The motion families of one task."""

    train: tuple[str, ...]
    """Families the skill policies train on (other draws of them are the validation and held-out motions)."""
    held_out: tuple[str, ...]
    """Families no policy trains on: held-out motions of an unseen kind."""
    extra: tuple[str, ...] = ()
    """Families a benchmark may add to the training (and validation) motions; never held out."""

    @property
    def all(self) -> tuple[str, ...]:
        return self.train + self.held_out + self.extra


TASK_FAMILIES = {"stand": MotionFamilies(train=("kick", "squat", "wave"), held_out=("march",)),
                 "floor": MotionFamilies(train=("squat", "weight_shift", "kick", "wave"), held_out=("step",),
                                         extra=("combo",))}
"""The registry: each task's families, by the task's name (:attr:`~.skill_config.SkillTaskConfig.name`)."""
FAMILIES = tuple(dict.fromkeys(f for t in TASK_FAMILIES.values() for f in t.all))
"""Every motion family of either task."""
STANCE = {"hip_pitch": -0.3, "knee": 0.6, "ankle_pitch": -0.3}
"""Neutral stance [rad] by joint-name suffix (knees slightly bent); every other joint 0."""
FLOOR_TRANSFER_S = (1.0, 1.4)
"""Range of a kick's or a step's weight transfer [s] between the stance and one sole (the screening of
:func:`~.motions.make_motions` slows the draws the soles cannot carry)."""
FLOOR_ACROSS_S = (1.4, 2.0)
"""Range of a step's weight transfer [s] from one sole across to the other (twice the distance)."""
FLOOR_SWING_S = (0.3, 0.5)
"""Range of each of a kick's swings [s]: back, forward, set down."""
COMBO_TRANSFER_S = (0.4, 1.0)
"""Range of a combo motion's weight transfers [s]: the slowest ask of the floor what the weight shifts and kicks do
(the zero-moment point up to about 0.1 m outside the soles), the fastest across the stance some 0.5 m (stepping in
place asks for 0.3 m)."""


def stance(robot: Robot) -> np.ndarray:
    """The neutral stance [rad], shape (n_dof,): :data:`STANCE` by joint-name suffix, clipped into the limits."""
    q = np.zeros(robot.n_dof)
    for i, name in enumerate(robot.joint_names):
        for suffix, v in STANCE.items():
            if name.endswith(suffix):
                q[i] = v
    return np.clip(q, robot.lower, robot.upper)


def leg_keys(rng, task: str, family: str, home: np.ndarray, duration: float, shift=None):
    """Sole keyframes of ``family`` in ``task``: times [s], positions (K, 2, 3) [m] and the drawn parameters;
    ``home`` (2, 3) the stance soles, ``shift`` (floor) the sideways shifts that put the weight over each sole."""
    if task == "floor" and family not in ("squat", "wave"):
        return _floor_leg_keys(rng, family, home, duration, shift)
    return _leg_keys(rng, family, home, duration)


def _min_jerk(s):
    return 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5


def keyframes(t: np.ndarray, times, values) -> np.ndarray:
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


def arm_keys(rng, robot: Robot, family: str, duration: float, side: str | None = None):
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


def _floor_leg_keys(rng, family: str, home: np.ndarray, duration: float, shift: tuple[float, float]):
    """Sole keyframes (times [s], positions (K, 2, 3) [m]) of the families that move the weight; ``shift[f]``: the
    sideways shift [m] that puts the centre of mass above sole f."""
    up, fwd, side = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])

    def over(f, frac=1.0):
        return home + frac * shift[f] * side

    def kick(f, frac=1.0):
        """Sole f's kick from the other sole, the weight ``frac`` of the way over it: (weight over it, back key,
        forward key, forward [m], up [m])."""
        back, out_x, out_z = rng.uniform(0.02, 0.05), rng.uniform(0.06, 0.12), rng.uniform(0.04, 0.08)
        w = over(1 - f, frac)
        k1, k2 = w.copy(), w.copy()
        k1[f] += -back * fwd + 0.6 * out_z * up
        k2[f] += out_x * fwd + out_z * up
        return w, k1, k2, out_x, out_z

    if family == "weight_shift":
        first = int(rng.integers(2))
        frac = rng.uniform(0.5, 0.9, size=2)
        t = np.sort(rng.uniform([0.15, 0.4, 0.65], [0.3, 0.55, 0.8])) * duration
        keys = [home, over(first, frac[0]), over(1 - first, frac[1]), home, home]
        return [0.0, t[0], t[1], t[2], duration], keys, {"first_foot": first, "fraction": frac.tolist()}
    if family == "kick":
        f = int(rng.integers(2))  # the kicking foot; the other carries the weight
        w, k1, k2, out_x, out_z = kick(f, rng.uniform(0.8, 0.95))
        gaps = np.concatenate([rng.uniform(*FLOOR_TRANSFER_S, size=1), rng.uniform(0.05, 0.25, size=1),
                               rng.uniform(*FLOOR_SWING_S, size=3), rng.uniform(0.05, 0.2, size=1),
                               rng.uniform(*FLOOR_TRANSFER_S, size=1)])
        times, scale = _fit(rng.uniform(0.05, 0.2) + np.cumsum(gaps), duration)
        return [0.0] + times + [duration], [home, w, w, k1, k2, w, w, home, home], {
            "foot": f, "forward_m": out_x, "up_m": out_z, "time_scale": scale}
    if family == "step":
        return _step_keys(rng, home, duration, over)
    if family == "combo":
        return _combo_keys(rng, home, duration, over, kick)
    raise ValueError(family)


def _combo_keys(rng, home, duration: float, over, kick):
    """Keyframes of a ``combo`` motion: see the module docstring. Events are drawn until the next would leave no
    time to return (at least one); the plan is then played faster where it overruns the motion."""
    times, keys, plan = [0.0], [home], []
    t = rng.uniform(0.05, 0.15) * duration
    for _ in range(3):
        kind, f = ("shift", "kick", "kick")[int(rng.integers(3))], int(rng.integers(2))
        if kind == "shift":  # weight over sole f, a weight shift's fraction of the way, held there
            gaps, event = rng.uniform(*COMBO_TRANSFER_S, size=1), [over(f, rng.uniform(0.5, 1.0))]
            gaps, event = np.append(gaps, rng.uniform(0.05, 0.4)), event + event
        else:  # weight over the other sole, sole f kicks back, forward and is set down
            w, k1, k2, _, _ = kick(f)
            gaps = np.concatenate([rng.uniform(*COMBO_TRANSFER_S, size=1), rng.uniform(0.2, 0.35, size=3)])
            event = [w, k1, k2, w]
        if plan and t + gaps.sum() + COMBO_TRANSFER_S[0] > duration:
            break
        times += list(t + np.cumsum(gaps))
        keys += event
        t = times[-1]
        plan.append(f"{kind}{f}")
    t += rng.uniform(*COMBO_TRANSFER_S)
    times, keys = times + [t], keys + [home]
    scale = min(1.0, 0.95 * duration / t)
    return [x * scale for x in times] + [duration], keys + [home], {"plan": plan, "time_scale": scale}


def _fit(times: np.ndarray, duration: float) -> tuple[list[float], float]:
    """Keyframe times [s] played faster where they overrun 97 % of the motion (the rest a hold in the stance), and
    the factor."""
    scale = min(1.0, 0.97 * duration / float(times[-1]))
    return [float(x) * scale for x in times], scale


def _step_keys(rng, home, duration: float, over):
    """Keyframes of a ``step`` motion: the weight over one sole, the other foot lifted (knee up, the sole ahead or
    behind at the top) and set down where it stood, once or twice; then, drawn half the time, the weight across and
    the other foot lifted once (in motions of 5 s or more: in 4 s no transfer across leaves time to return); the
    weight back to the stance. Every lift draws its height, reach and tempo, every transfer its duration; lifts are
    drawn until the next would leave no time to return (at least one)."""
    up, fwd = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0])
    first = int(rng.integers(2))  # the first foot lifted
    feet = [first] * int(rng.integers(1, 3)) + ([1 - first] if rng.random() < 0.5 else [])
    frac = rng.uniform(0.8, 0.95, size=2)  # how far the weight goes over each sole
    back = rng.uniform(*FLOOR_TRANSFER_S)  # the weight back to the stance at the end
    t, times, keys, plan, lifts, stance = rng.uniform(0.05, 0.2), [0.0], [home], [], [], None
    for f in feet:
        w = over(1 - f, frac[1 - f])
        k = w.copy()
        height, reach = rng.uniform(0.03, 0.07), rng.uniform(-0.02, 0.04)
        k[f] += height * up + reach * fwd
        move = rng.uniform(*(FLOOR_ACROSS_S if stance is not None else FLOOR_TRANSFER_S))
        swing = np.concatenate([rng.uniform(0.2, 0.35, size=1), rng.uniform(0.0, 0.15, size=1),
                                rng.uniform(0.2, 0.35, size=1), rng.uniform(0.05, 0.15, size=1)])
        gaps, event = swing, [k, k, w, w]
        if stance != 1 - f:
            gaps, event = np.concatenate([[move], swing]), [w] + event
        if plan and t + gaps.sum() + back > 0.97 * duration:
            break
        times += list(t + np.cumsum(gaps))
        keys += event
        t, stance = times[-1], 1 - f
        plan.append("LR"[f])
        lifts.append({"height_m": float(height), "reach_m": float(reach)})
    times, scale = _fit(np.array(times[1:] + [t + back]), duration)
    return [0.0] + times + [duration], keys + [home, home], {
        "first_foot": first, "plan": "".join(plan), "lifts": lifts, "time_scale": scale}
