"""Reference motions on the floor: keyframes of the soles (solved by the foot IK) and of the arms, with the base
that keeps the planted feet where they stand.

Each motion is drawn as on the stand (:mod:`wresdyn.skills.motions`: sole keyframes in the pelvis-fixed frame,
Pinocchio IK, minimum-jerk between keyframes), then placed on the floor: a sole at the lowest height is *planted*,
and the reference base moves so that every planted sole stays where it stood (the feet never slide in the
reference), upright (the soles keep their stance orientation relative to the pelvis). Motions that lift a foot
first shift the weight: the soles move sideways until the whole robot's centre of mass (Pinocchio, the pelvis
included) is above the stance sole, so a quasi-static reference can stand on one foot. Families:

- ``squat``: both soles rise together (the pelvis lowers), once or twice;
- ``weight_shift``: the centre of mass moves over one sole, then over the other, and back;
- ``kick``: weight onto one foot, the other sole pulled back and up, thrust forward and returned, weight back;
- ``wave``: one arm raised sideways waves while the legs hold the stance;
- ``step`` (held out from training by default): stepping in place, weight over one foot, the other lifted and
  set down, then the other side;
- ``combo`` (an optional training family, :data:`FLOOR_EXTRA_FAMILIES`): compositions of the weight shifts' and
  kicks' keyframes, as many as fit the motion (up to three) in a random order with random durations: single-leg
  support on either foot, the weight carried straight across from one foot to the other, transfers slow enough to
  follow and too fast for any robot to follow (the floor would have to pull), where a policy must give up tracking
  to keep its balance. The lifted foot only ever kicks (back, then forward); it is never just lifted and set down.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..data.ik import FootIK
from ..robot.description import Robot, RobotError
from ..robot.ground import standing_state
from ..robot.pinocchio_model import build_pinocchio
from .motions import _arm_keys, _keyframes, _leg_keys, stance

__all__ = ["FLOOR_FAMILIES", "FLOOR_TRAIN_FAMILIES", "FLOOR_HELD_OUT_FAMILIES", "FLOOR_EXTRA_FAMILIES", "FloorMotion",
           "make_floor_motions", "PLANTED_TOL"]

FLOOR_FAMILIES = ("squat", "weight_shift", "kick", "wave", "step", "combo")
FLOOR_TRAIN_FAMILIES = ("squat", "weight_shift", "kick", "wave")
"""Families the floor skills train on (other draws of them are the validation and held-out motions)."""
FLOOR_HELD_OUT_FAMILIES = ("step",)
"""The family no floor skill trains on."""
FLOOR_EXTRA_FAMILIES = ("combo",)
"""Families a benchmark may add to the training (and validation) motions; never held out."""
COMBO_TRANSFER_S = (0.4, 1.0)
"""Range of a combo motion's weight transfers [s]: the slowest ask of the floor what the weight shifts and kicks do
(the zero-moment point up to about 0.1 m outside the soles), the fastest across the stance some 0.5 m (stepping in
place asks for 0.3 m)."""
PLANTED_TOL = 0.002
"""A sole less than this above the lowest sole is planted [m]."""


@dataclass
class FloorMotion:
    """One reference motion on the floor, sampled at ``rate_hz``."""

    name: str
    family: str
    q: np.ndarray
    """Reference joint positions [rad], shape (T, n_dof)."""
    qd: np.ndarray
    """Reference joint velocities [rad/s], shape (T, n_dof) (central differences)."""
    base: np.ndarray
    """Reference base pose in the world, [x y z qx qy qz qw] ([m], unit quaternion), shape (T, 7)."""
    planted: np.ndarray
    """Which soles (left, right) the reference keeps on the floor, bool, shape (T, 2)."""
    feet: np.ndarray
    """Reference sole positions in the pelvis frame [m], shape (T, 2, 3)."""
    params: dict = field(default_factory=dict)


def _com(robot: Robot, model, data, q: np.ndarray) -> np.ndarray:
    """Whole-robot centre of mass in the stand frame [m] (Pinocchio's fixed-base model leaves the pelvis out)."""
    import pinocchio as pin

    from scipy.spatial.transform import Rotation as R

    c = pin.centerOfMass(model, data, q)
    m = pin.computeTotalMass(model)
    xp = robot.joint_X_p[0]
    pelvis = xp[:3] + R.from_quat(xp[3:]).apply(robot.body_com[0])
    m0 = float(robot.body_mass[0])
    return (m * c + m0 * pelvis) / (m + m0)


def _shift_over(robot: Robot, ik: FootIK, q0, home, rot, foot: int, iterations: int = 6) -> float:
    """Sideways shift of both soles [m] that puts the centre of mass above sole ``foot`` (0 left, 1 right)."""

    model = build_pinocchio(robot)
    data = model.createData()
    d, q = 0.0, q0
    for _ in range(iterations):
        pos = home.copy()
        pos[:, 1] += d
        q, _ = ik.solve(pos[None].reshape(1, 2, 3)[0], None if ik.position_only else rot, q)
        d = d + (_com(robot, model, data, q)[1] - (home[foot, 1] + d))
    return float(d)


def _floor_leg_keys(rng, family: str, home: np.ndarray, duration: float, shift: tuple[float, float]):
    """Sole keyframes (times [s], positions (K, 2, 3) [m]) of the families that move the weight; ``shift[f]``: the
    sideways shift [m] that puts the centre of mass above sole f."""
    up, fwd, side = np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0])

    def over(f, frac=1.0):
        return home + frac * shift[f] * side

    def kick(f):
        """Sole f's kick from the other sole: (weight over it, back key, forward key, forward [m], up [m])."""
        back, out_x, out_z = rng.uniform(0.02, 0.05), rng.uniform(0.06, 0.12), rng.uniform(0.04, 0.08)
        w = over(1 - f)
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
        w, k1, k2, out_x, out_z = kick(f)
        times = np.array([0.0, 0.2, 0.3, 0.45, 0.6, 0.72, 0.85, 1.0]) * duration
        return list(times), [home, w, w, k1, k2, w, home, home], {"foot": f, "forward_m": out_x, "up_m": out_z}
    if family == "step":
        first = int(rng.integers(2))  # the first foot lifted
        lift = rng.uniform(0.03, 0.06)
        times, keys = [0.0], [home]
        seg = 0.9 * duration / 2
        for i in range(2):
            f = (first + i) % 2
            w = over(1 - f)
            k = w.copy()
            k[f] += lift * up
            t0 = 0.05 * duration + i * seg
            times += [t0 + 0.3 * seg, t0 + 0.5 * seg, t0 + 0.7 * seg, t0 + 0.85 * seg]
            keys += [w, k, w, w]
        return times + [0.97 * duration, duration], keys + [home, home], {"lift_m": lift, "first_foot": first}
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


def _place(robot: Robot, floating: Robot, feet: np.ndarray, q: np.ndarray):
    """The reference base (T, 7) and planted soles (T, 2) of sole paths ``feet`` (T, 2, 3) in the stand frame."""

    low = feet[:, :, 2].min(axis=1)
    planted = feet[:, :, 2] - low[:, None] < PLANTED_TOL
    start = standing_state(floating, q[0]).base_pose
    home = feet[0]
    base = np.tile(start, (len(q), 1))
    shift = np.where(planted[..., None], home[None] - feet, 0.0).sum(1) / planted.sum(1, keepdims=True)
    base[:, :2] += shift[:, :2]
    base[:, 2] -= low - low[0]
    return base, planted


def make_floor_motion(robot: Robot, floating: Robot, ik: FootIK, family: str, duration: float, rate_hz: float,
                      rng: np.random.Generator, name: str, shift: tuple[float, float], ik_tol: float = 0.005,
                      max_draws: int = 20, side: str | None = None) -> FloorMotion:
    """Draw one floor motion of ``family`` (redrawn until the sole IK reaches every keyframe path within ``ik_tol``
    [m])."""
    if family not in FLOOR_FAMILIES:
        raise ValueError(f"unknown floor motion family {family!r}; choose from {FLOOR_FAMILIES}")
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    q0 = stance(robot)
    home, rot = ik.forward(q0)
    rots = np.broadcast_to(rot, (len(t),) + rot.shape)
    for _ in range(max_draws):
        if family in ("squat", "wave"):
            lt, lk, lp = _leg_keys(rng, family, home, duration)
        else:
            lt, lk, lp = _floor_leg_keys(rng, family, home, duration, shift)
        at, ak, ap = _arm_keys(rng, robot, "wave" if family == "wave" else "none", duration, side)
        pos = _keyframes(t, lt, lk)
        q, err = ik.solve_path(pos, None if ik.position_only else rots, q0)
        if float(err[:, :, 0].max()) > ik_tol:
            continue
        q = np.clip(q + _keyframes(t, at, ak), robot.lower, robot.upper)
        feet = np.array([ik.forward(x)[0] for x in q])
        base, planted = _place(robot, floating, feet, q)
        return FloorMotion(name, family, q, np.gradient(q, 1.0 / rate_hz, axis=0), base, planted, feet,
                           {**lp, **ap, "ik_max_error_m": float(err[:, :, 0].max())})
    raise RobotError(f"{robot.source}: no {family} floor motion reached its sole keyframes within {ik_tol} m in "
                     f"{max_draws} draws")


def make_floor_motions(robot: Robot, floating: Robot, counts: dict[str, int], duration: float = 4.0,
                       rate_hz: float = 500.0, seed: int = 0, families=FLOOR_TRAIN_FAMILIES,
                       held_out=FLOOR_HELD_OUT_FAMILIES, extra=()) -> dict[str, list[FloorMotion]]:
    """Draw the floor motion set: ``counts`` maps a split to motions per family (``families`` for every split,
    ``held_out`` families in ``heldout`` only, ``extra`` families in every other split, drawn after the others so
    that those are the same with or without them); each split draws from its own stream.

    Args:
        robot: The robot on its stand (fixed base, sole frames ``left_sole``/``right_sole``): the IK's frame.
        floating: The same robot with a free base (its standing height).
    """
    if robot.base != "fixed" or floating.base != "floating":
        raise RobotError(f"{robot.source}: floor motions need the robot on its stand and with a free base")
    ik = FootIK(robot)
    q0 = stance(robot)
    home, rot = ik.forward(q0)
    shift = (_shift_over(robot, ik, q0, home, rot, 0), _shift_over(robot, ik, q0, home, rot, 1))
    out = {}
    for s, (split, per) in enumerate(counts.items()):
        rng = np.random.default_rng([seed, s, 7])
        first = int(np.random.default_rng([seed, s, 1]).integers(2))
        fams = tuple(families) + (tuple(held_out) if split == "heldout" else tuple(extra))
        out[split] = [make_floor_motion(robot, floating, ik, f, duration, rate_hz, rng, f"{split}_{f}_{i}", shift,
                                        side=("left", "right")[(first + i) % 2] if f == "wave" else None)
                      for f in fams for i in range(per)]
    return out
