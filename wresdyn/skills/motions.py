"""Reference motions of the skills, on the stand and on the floor: keyframes of the soles (solved by the foot IK) and
of the arm joints, drawn from the families of :mod:`.families`; on the floor with the base that keeps the planted
feet where they stand.

The leg joints come from the sole IK of :mod:`wresdyn.data.ik` (Pinocchio; the excitation's machinery), the arm and
waist joints from joint-space keyframes by name pattern, minimum-jerk between keyframes. A motion starts and ends at
rest in the neutral stance (:data:`~.families.STANCE`), the start state of every episode in :mod:`wresdyn.skills.env`.

On the floor (:func:`make_motions` with ``floating``) each motion is drawn in the pelvis-fixed frame, then placed: a
sole at the lowest height is *planted*, and the reference base moves so that every planted sole stays where it stood
(the feet never slide in the reference), upright (the soles keep their stance orientation relative to the pelvis).
Motions that lift a foot first shift the weight: the soles move sideways until the whole robot's centre of mass
(Pinocchio, the pelvis included) is above the stance sole, so a quasi-static reference can stand on one foot.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import zlib
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ..data.ik import FootIK
from ..robot.description import Robot, RobotError
from ..robot.ground import standing_state
from ..robot.pinocchio_model import build_pinocchio
from .families import FAMILIES, TASK_FAMILIES, arm_keys, keyframes, leg_keys, stance
from .feasibility import screen as screen_feasibility

__all__ = ["TASK_FAMILIES", "FAMILIES", "Motion", "MotionSet", "make_motion", "make_motions", "stance", "PLANTED_TOL",
           "joint_velocity", "pool_workers"]

PLANTED_TOL = 0.002
"""A sole less than this above the lowest sole is planted [m]."""
DURATION = {"stand": 2.0, "floor": 4.0}
"""Default length of a motion of each task [s]."""


@dataclass
class Motion:
    """One reference motion, sampled at its set's ``rate_hz``."""

    name: str
    family: str
    q: np.ndarray
    """Reference joint positions [rad], shape (T, n_dof), sample k at t = k / rate_hz."""
    qd: np.ndarray
    """Reference joint velocities [rad/s], shape (T, n_dof) (central differences)."""
    feet: np.ndarray
    """Reference sole positions in the pelvis (stand) frame [m], shape (T, n_feet, 3) (forward kinematics of ``q``)."""
    params: dict = field(default_factory=dict)
    base: np.ndarray | None = None
    """On the floor: the reference base pose in the world, [x y z qx qy qz qw] ([m], unit quaternion), shape (T, 7);
    ``None`` on the stand."""
    planted: np.ndarray | None = None
    """On the floor: which soles (left, right) the reference keeps on the floor, bool, shape (T, 2)."""
    screen: str = ""
    """What the feasibility screening did (:func:`make_motion`): ``"ok"``, ``"slowed x1.3"``, with ``", 2 redraws"``
    when earlier draws failed; empty where not screened (the stand, ``combo``)."""


@dataclass
class MotionSet:
    """Motions of one robot at one rate, by split (``train``, ``validation``, ``heldout``); ``motions[split]`` is
    :meth:`split`."""

    rate_hz: float
    splits: dict[str, list[Motion]]

    def split(self, name: str) -> list[Motion]:
        return self.splits.get(name, [])

    def __getitem__(self, name: str) -> list[Motion]:
        return self.splits[name]


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

    model = ik.model  # ``robot``'s Pinocchio model (the IK's robot), with data of its own
    data = model.createData()
    d, q = 0.0, q0
    for _ in range(iterations):
        pos = home.copy()
        pos[:, 1] += d
        q, _ = ik.solve(pos[None].reshape(1, 2, 3)[0], None if ik.position_only else rot, q)
        d = d + (_com(robot, model, data, q)[1] - (home[foot, 1] + d))
    return float(d)


class FloorCache:
    """What every floor draw of one free-base robot shares, made once per :func:`make_motions` call (and pool worker)
    rather than once per draw: the robot's Pinocchio model (the screening's) and the standing base pose of each start
    configuration met (:func:`~wresdyn.robot.ground.standing_state` builds a Newton model each call; the motions
    start in the stance, so one is usually met). Only reads the robot: the draws are those made without it."""

    def __init__(self, floating: Robot):
        self.robot = floating
        self.model = build_pinocchio(floating)
        self._stands: dict[bytes, np.ndarray] = {}

    def stand(self, q: np.ndarray) -> np.ndarray:
        """The standing base pose [x y z qx qy qz qw] of joints ``q`` [rad] (n_dof,), float64 (a copy)."""
        q = np.asarray(q, dtype=np.float64)
        key = q.tobytes()  # the exact configuration: a pose is reused for the same bits only
        if key not in self._stands:
            self._stands[key] = standing_state(self.robot, q).base_pose
        return self._stands[key].copy()


def _place(floor: FloorCache, feet: np.ndarray, q: np.ndarray):
    """The reference base (T, 7) and planted soles (T, 2) of sole paths ``feet`` (T, 2, 3) in the stand frame."""

    low = feet[:, :, 2].min(axis=1)
    planted = feet[:, :, 2] - low[:, None] < PLANTED_TOL
    start = floor.stand(q[0])
    home = feet[0]
    base = np.tile(start, (len(q), 1))
    shift = np.where(planted[..., None], home[None] - feet, 0.0).sum(1) / planted.sum(1, keepdims=True)
    base[:, :2] += shift[:, :2]
    base[:, 2] -= low - low[0]
    return base, planted


SLOWER = (1.0, 1.15, 1.3, 1.5, 1.75, 2.0)
"""Time stretches the screening tries on a floor draw the flat soles cannot carry, in this order: the keyframe
times [s] times the factor, the motion's length kept (the end a longer hold in the stance); a factor that would
push the last keyframe past the end is not tried, and a draw no factor makes feasible is redrawn."""
UNSCREENED = ("combo",)
"""Floor families drawn without screening: ``combo`` asks for transfers too fast to follow on purpose."""


def _play(robot: Robot, ik: FootIK, leg, arm, t: np.ndarray, rate_hz: float, ik_tol: float,
          floor: FloorCache | None, family: str, name: str, params: dict) -> Motion | None:
    """The motion of keyframes ``leg`` (times, sole positions) and ``arm`` (times, joint offsets) sampled at ``t``,
    placed on ``floor``'s robot's floor (``None``: the stand); ``None`` where the sole IK misses a keyframe path by
    more than ``ik_tol`` [m]."""
    q0 = stance(robot)
    home, rot = ik.forward(q0)
    pos = keyframes(t, *leg)
    q, err = ik.solve_path(pos, None if ik.position_only else np.broadcast_to(rot, (len(t),) + rot.shape), q0)
    if float(err[:, :, 0].max()) > ik_tol:
        return None
    q = np.clip(q + keyframes(t, *arm), robot.lower, robot.upper)
    qd = joint_velocity(q, rate_hz)
    feet = np.array([ik.forward(x)[0] for x in q])
    params = {**params, "ik_max_error_m": float(err[:, :, 0].max())}
    if floor is None:
        return Motion(name, family, q, qd, feet, params)
    base, planted = _place(floor, feet, q)
    return Motion(name, family, q, qd, feet, params, base=base, planted=planted)


def joint_velocity(q: np.ndarray, rate_hz: float) -> np.ndarray:
    """A motion's reference joint velocities [rad/s], shape (T, n_dof), from its positions ``q`` (T, n_dof) [rad]
    sampled at ``rate_hz``: central differences (one-sided at the ends)."""
    return np.gradient(q, 1.0 / rate_hz, axis=0)


def _stretch(keys, factor: float, duration: float):
    """Keyframes ``keys`` (times [s], values) played ``factor`` times slower, the last keyframe kept at ``duration``
    (the hold it ends with); ``None`` where the one before would pass it."""
    times, values = keys
    if factor > 1.0 and times[-2] * factor > duration:
        return None
    return [x * factor for x in times[:-1]] + [duration], values


def make_motion(robot: Robot, ik: FootIK, family: str, duration: float, rate_hz: float, rng: np.random.Generator,
                name: str, ik_tol: float = 0.005, max_draws: int = 20, side: str | None = None, *,
                floating: Robot | None = None, shift: tuple[float, float] | None = None,
                screen: bool = False, floor_cache: FloorCache | None = None) -> Motion:
    """Draw one motion of ``family`` (redrawn until the sole IK reaches every keyframe path within ``ik_tol`` [m]);
    ``side`` fixes a wave's arm (default: drawn). ``floating``: the robot with a free base, to place the motion on
    its floor (a floor family; ``shift``: the weight shifts over each sole).

    ``screen`` (the floor): a draw must pass :func:`~.feasibility.screen` (the zero-moment point inside the planted
    soles, every joint torque within its effort limit); one that does not is slowed by the first factor of
    :data:`SLOWER` that passes, else redrawn. :attr:`Motion.screen` says which; ``params`` keeps the measure.
    ``floor_cache``: ``floating``'s :class:`FloorCache`, shared by many draws (default: made here)."""
    task = "stand" if floating is None else "floor"
    if family not in TASK_FAMILIES[task].all:
        raise ValueError(f"unknown {task} motion family {family!r}; choose from {TASK_FAMILIES[task].all}")
    screen = screen and floating is not None and family not in UNSCREENED
    floor = None if floating is None else floor_cache if floor_cache is not None else FloorCache(floating)
    t = np.arange(int(round(duration * rate_hz)) + 1) / rate_hz
    home, _ = ik.forward(stance(robot))
    worst = None
    for draw in range(max_draws):
        lt, lk, lp = leg_keys(rng, task, family, home, duration, shift)
        at, ak, ap = arm_keys(rng, robot, family, duration, side)
        for factor in SLOWER if screen else (1.0,):
            leg, arm = _stretch((lt, lk), factor, duration), _stretch((at, ak), factor, duration)
            if leg is None or arm is None:
                break
            m = _play(robot, ik, leg, arm, t, rate_hz, ik_tol, floor, family, name, {**lp, **ap})
            if m is None:  # the IK missed a keyframe path: redraw
                break
            if not screen:
                return m
            m.params.update(screen_feasibility(floating, m, rate_hz, floor.model), slowed=factor, redraws=draw)
            if m.params["feasible"]:
                m.screen = ("ok" if factor == 1.0 else f"slowed x{factor:g}") + (f", {draw} redraws" if draw else "")
                return m
            worst = m.params
    if worst is not None:
        raise RobotError(f"{robot.source}: no {family} floor motion the flat soles carry in {max_draws} draws, each "
                         f"slowed up to x{SLOWER[-1]:g} (last: zero-moment point {1e3 * worst['zmp_margin_m']:+.0f} "
                         f"mm inside the soles, torque {worst['effort_ratio']:.2f} of the limit; longer motions "
                         f"leave time to slow it)")
    raise RobotError(f"{robot.source}: no {family} {task} motion reached its sole keyframes within {ik_tol} m in "
                     f"{max_draws} draws")


def _key(name: str) -> int:
    """A stable integer of a split's or a family's name, for the seed streams."""
    return zlib.crc32(name.encode())


POOL_MOTIONS_PER_WORKER = 8
"""Automatic pools give each worker at least this many motions: a worker spends about as long starting (imports,
robots: 2.5 s on the project's CPU) as drawing 5 motions (0.49 s each at full size), so fewer would cost more than
they save; 8 also leaves cores to the runs beside it (``benchmarks/results/floor_fair/speed_cpu/``)."""


def pool_workers(workers: int, n: int) -> int:
    """Processes that draw ``n`` floor motions with ``workers`` asked (0: automatic, the host's usable cores but at
    most one per :data:`POOL_MOTIONS_PER_WORKER` motions; on a host of at most 2 cores 1: the serial path, no process
    started), never more than ``n``, at least 1."""
    if workers == 0:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        workers = 1 if cores <= 2 else min(cores, n // POOL_MOTIONS_PER_WORKER)
    return max(1, min(int(workers), n))


_WORKER: dict = {}
"""A pool worker's robots, foot IK and :class:`FloorCache`, made once by :func:`_init_worker`."""


def _init_worker(robot: Robot, floating: Robot, frames) -> None:
    """Start a pool worker: the robots arrive as their :func:`~wresdyn.robot.description.load_robot` calls (loaded
    here again, the file's hash checked), the foot IK and the floor's cache are built here."""
    _WORKER.update(robot=robot, floating=floating, ik=FootIK(robot) if frames is None else FootIK(robot, frames),
                   floor=FloorCache(floating))


def _draw(job: tuple) -> Motion:
    """One floor motion in a pool worker: ``job`` is :func:`make_motion`'s arguments after the robots and IK, its
    random stream as the stream's seed."""
    family, duration, rate_hz, stream, name, side, max_draws, shift, screen = job
    w = _WORKER
    return make_motion(w["robot"], w["ik"], family, duration, rate_hz, np.random.default_rng(stream), name,
                       side=side, max_draws=max_draws, floating=w["floating"], shift=shift, screen=screen,
                       floor_cache=w["floor"])


def make_motions(robot: Robot, counts: dict[str, int], duration: float | None = None, rate_hz: float = 500.0,
                 seed: int = 0, frames=None, *, floating: Robot | None = None, families=None, held_out=None,
                 extra=(), screen: bool = True, max_draws: int = 20, workers: int = 1) -> MotionSet:
    """Draw the motion set of the task on the stand, or with ``floating`` on the floor: ``counts`` maps a split to
    motions per family (``families`` for every split, ``held_out`` families in ``heldout`` only, ``extra`` families
    in every other split, drawn after the others so that those are the same with or without them); each split draws
    from its own stream.

    Args:
        robot: The robot on its stand (fixed base) with sole frames (``frames``, default the IK's
            ``left_sole``/``right_sole``): the IK's frame.
        counts: Motions per family and split, e.g. ``{"train": 4, "validation": 1, "heldout": 2}``.
        duration: Length of each motion [s] (default: 2 s on the stand, 4 s on the floor).
        rate_hz: Sample rate [Hz] (the simulation's).
        seed: Seed of the draws.
        floating: The same robot with a free base (its standing height): the motions are placed on its floor.
        families, held_out, extra: The task's families (default: its :data:`TASK_FAMILIES` train and held-out
            ones, no extra).
        screen: On the floor, keep only draws the flat soles can carry, slowed where needed (:func:`make_motion`;
            ``False``: every draw as drawn, for studies of infeasible references).
        max_draws: Draws of each motion before it is given up (a one-line error).
        workers: On the floor, processes that draw the motions (0: automatic, :func:`pool_workers`): each motion
            has its own stream, so the set is bit for bit the one drawn serially, in the same order. The robots
            travel as their ``load_robot`` calls; a robot not made by ``load_robot`` is drawn serially. On the stand
            (one stream per split, in order) always serial.

    The waves of a split alternate between the arms (the first arm drawn per split), so a split of two or more waves
    has both: training on one arm's waves alone leaves a policy untaught for the other's.
    """
    task = "stand" if floating is None else "floor"
    if floating is None and robot.base != "fixed":
        raise RobotError(f"{robot.source}: the skill motions are drawn on the stand (a fixed base)")
    if floating is not None and (robot.base != "fixed" or floating.base != "floating"):
        raise RobotError(f"{robot.source}: floor motions need the robot on its stand and with a free base")
    fam = TASK_FAMILIES[task]
    families = fam.train if families is None else tuple(families)
    held_out = fam.held_out if held_out is None else tuple(held_out)
    duration = DURATION[task] if duration is None else duration
    ik = FootIK(robot) if frames is None else FootIK(robot, tuple(frames))
    shift = None
    if floating is not None:
        q0 = stance(robot)
        home, rot = ik.forward(q0)
        shift = (_shift_over(robot, ik, q0, home, rot, 0), _shift_over(robot, ik, q0, home, rot, 1))
    splits = {}
    for s, (split, per) in enumerate(counts.items()):
        fams = families + (held_out if split == "heldout" else tuple(extra))
        if floating is None:  # one stream per split, by its place in ``counts``
            rng = np.random.default_rng([seed, s])
            first = int(np.random.default_rng([seed, s, 1]).integers(2))
            splits[split] = [make_motion(robot, ik, f, duration, rate_hz, rng, f"{split}_{f}_{i}",
                                         side=("left", "right")[(first + i) % 2] if f == "wave" else None,
                                         max_draws=max_draws)
                             for f in fams for i in range(per)]
            continue
        # on the floor one stream per motion, by the split's and the family's names: a split's draws never repeat
        # another's whatever ``counts`` holds, and the first n of a family are the same at any larger count
        first = int(np.random.default_rng([seed, _key(split), 1]).integers(2))
        splits[split] = [(f, duration, rate_hz, [seed, _key(split), 7, _key(f), i], f"{split}_{f}_{i}",
                          ("left", "right")[(first + i) % 2] if f == "wave" else None, max_draws, shift, screen)
                         for f in fams for i in range(per)]
    if floating is not None:
        jobs = [j for js in splits.values() for j in js]
        n = pool_workers(workers, len(jobs))
        if n > 1 and all(getattr(r, "_load_args", None) is not None for r in (robot, floating)):
            with ProcessPoolExecutor(n, mp_context=mp.get_context("spawn"), initializer=_init_worker,
                                     initargs=(robot, floating, None if frames is None else tuple(frames))) as pool:
                done = iter(list(pool.map(_draw, jobs)))
        else:
            floor = FloorCache(floating)
            done = (make_motion(robot, ik, f, d, r, np.random.default_rng(st), nm, side=sd, max_draws=md,
                                floating=floating, shift=sh, screen=sc, floor_cache=floor)
                    for f, d, r, st, nm, sd, md, sh, sc in jobs)
        splits = {k: [next(done) for _ in js] for k, js in splits.items()}
    return MotionSet(float(rate_hz), splits)
