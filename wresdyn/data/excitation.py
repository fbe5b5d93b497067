"""Excitation trajectories: the joint commands executed on the (real) robot under PD control.

Training and held-out data use the paper's excitation (Sec. II-A): each sole follows a path on an
ellipsoid (eq. 2) inside that foot's reachable workspace, the leg joints come from the sole IK
(:mod:`wresdyn.data.ik`), and the waist and arm joints, which no foot target moves, get multisines within
their limits, so every joint is excited. eq. 2's angle rate is φ̇ = A_φ sin(ω_φ t): the foot sweeps the
ellipsoid with an instantaneous frequency that rises from 0 to A_φ / 2π and back, a chirp in disguise;
drawing A and ω per trajectory over a wide log-uniform band spreads the command energy from < 0.5 Hz to
several Hz (checked by :func:`~wresdyn.data.spectrum.band_fraction` and shown by
:func:`~wresdyn.data.spectrum.plot_spectrum`).

Out-of-distribution evaluation uses motion families never seen in training: joint-space ``chirp`` sweeps
and task-space ``kick`` swings (minimum-jerk point-to-point moves of one sole at a time).

The IK frames are any sites or bodies (:class:`ExcitationConfig` ``frames``, ``wresdyn collect --frames``): a
robot whose chains cannot follow a full pose gets position-only targets (:mod:`wresdyn.data.ik`). For robots
where foot targets make no sense (an arm) the joint-space mode (``mode = "joint"``,
:mod:`wresdyn.data.joint_excitation`) excites every joint
directly: ``multisine`` for train, validation and held-out, ``chirp`` and ``steps`` (minimum-jerk moves between
random joint positions) out of distribution. Each joint stays inside its limits, its command speed under
``joint_max_velocity``, and the torque the command needs (inverse dynamics of the nominal robot: inertia and
armature, gravity, damping and friction) under ``effort_fraction`` of its effort limit. :func:`plan` picks the
mode (``"auto"``: foot IK when the robot has all ``frames``, joint space otherwise) and prepares it.
Everything is drawn from a seeded :class:`numpy.random.Generator`.
"""

from __future__ import annotations

import dataclasses
import itertools
import time
from dataclasses import dataclass

import numpy as np

from ..robot.description import Robot, RobotError
from .ik import FootIK
from .joint_excitation import JointDynamics, effort_limit, generate_joint
from .signals import (
    FAMILIES,
    JOINT_FAMILIES,
    JOINT_OOD_FAMILIES,
    JOINT_TRAIN_FAMILIES,
    MODES,
    OOD_FAMILIES,
    TRAIN_FAMILIES,
    Excitation,
    ExcitationConfig,
    centre_amplitude,
    chirp,
    finite_limits,
    limit_margin,
    min_jerk,
    multisine,
)

__all__ = ["ExcitationConfig", "Excitation", "Workspace", "Plan", "FAMILIES", "TRAIN_FAMILIES", "OOD_FAMILIES",
           "JOINT_FAMILIES", "JOINT_TRAIN_FAMILIES", "JOINT_OOD_FAMILIES", "MODES", "foot_workspace", "ellipsoid_path",
           "generate", "plan"]


@dataclass
class Workspace:
    """Axis-aligned box of sole positions reachable with a level sole, per foot."""

    lo: np.ndarray
    """Lower corner per foot [m], shape (n_feet, 3)."""
    hi: np.ndarray
    """Upper corner per foot [m], shape (n_feet, 3)."""
    home: np.ndarray
    """Joint configuration whose soles are nearest the box centres, IK start [rad], shape (n_dof,)."""
    level: np.ndarray
    """Sole orientation in the neutral pose (the 'level' orientation), shape (n_feet, 3, 3)."""


PROGRESS_EVERY = 2.0
"""Seconds between progress lines of the workspace fitting loop (a round faster than that prints nothing)."""


def foot_workspace(ik: FootIK, cfg: ExcitationConfig, seed: int = 0, progress=None) -> Workspace:
    """Sample the reachable workspace of each sole with the sole level: random leg configurations inside the
    limits are moved to the nearest configuration with level soles (orientation-only IK) and their sole
    positions (FK) collected; the box spans the given per-axis quantiles of those positions. ``progress``: optional
    ``callable(str)`` receiving a line after the sampling and after each round of fitting the box into reach."""
    start = time.perf_counter()
    rng = np.random.default_rng(seed)
    robot = ik.robot
    q_ref = np.clip(robot.q0, ik.lower, ik.upper)
    _, level = ik.forward(q_ref)
    pts, confs = [], []
    for _ in range(cfg.workspace_samples):
        q = q_ref.copy()
        q[ik.dofs] = rng.uniform(ik.lower[ik.dofs], ik.upper[ik.dofs])
        if ik.position_only:  # no orientation to level: every sampled configuration is reachable as it is
            pts.append(ik.forward(q)[0])
            confs.append(q)
            continue
        qs, err = ik.solve(None, level, q)
        if (err[:, 1] < ik.config.rot_tol).all():
            pts.append(ik.forward(qs)[0])
            confs.append(qs)
    if len(pts) < 20:
        raise RobotError(f"{robot.source}: only {len(pts)} of {cfg.workspace_samples} sampled sole positions are "
                         "reachable with a level sole; cannot build the foot workspace")
    pts = np.asarray(pts)
    lo, hi = np.quantile(pts, cfg.workspace_quantiles[0], axis=0), np.quantile(pts, cfg.workspace_quantiles[1], axis=0)
    for f in range(len(lo) if len(lo) > 1 else 0):
        if abs(np.median(pts[:, f, 1])) <= cfg.min_foot_y:
            continue  # a frame on no clear side of the sagittal plane keeps its box
        side = np.sign(np.median(pts[:, f, 1]))
        if side > 0:
            lo[f, 1] = max(lo[f, 1], cfg.min_foot_y)
        else:
            hi[f, 1] = min(hi[f, 1], -cfg.min_foot_y)
    centre = 0.5 * (lo + hi)
    home = confs[int(np.argmin(np.linalg.norm(pts - centre, axis=2).sum(axis=1)))]
    if progress:
        progress(f"  {len(pts)} of {cfg.workspace_samples} sampled configurations usable "
                 f"({time.perf_counter() - start:.1f} s); checking the box is reachable (IK on a 5x5x5 grid per frame)")
    lo, hi = _shrink_to_reachable(ik, lo, hi, home, level, cfg, progress)
    if progress:
        size = ", ".join(f"{f} {100 * (hi[i] - lo[i]).min():.1f}-{100 * (hi[i] - lo[i]).max():.1f} cm"
                         for i, f in enumerate(ik.frames))
        progress(f"  workspace ready in {time.perf_counter() - start:.1f} s: box sides {size}")
    return Workspace(lo=lo, hi=hi, home=home, level=level)


def _shrink_to_reachable(ik: FootIK, lo, hi, home, level, cfg: ExcitationConfig, progress=None):
    """The reachable set is curved, so corners of the quantile box can be out of reach: each round, pull in by
    a tenth of the box size every face touched by an unreachable point of a 5x5x5 grid (``progress``: a line after
    a round when the last line is :data:`PROGRESS_EVERY` or more old)."""
    grid = np.array(list(itertools.product(np.linspace(0.0, 1.0, 5), repeat=3)))
    home_pos, _ = ik.forward(home)
    lo, hi = lo.copy(), hi.copy()
    last = time.perf_counter()
    for r in range(20):
        bad = False
        n_bad = 0
        for f in range(len(lo)):
            size = hi[f] - lo[f]
            pull_lo, pull_hi = np.zeros(3, dtype=bool), np.zeros(3, dtype=bool)
            for u in grid:
                pos = home_pos.copy()
                pos[f] = lo[f] + u * size
                _, err = ik.solve(pos, level, home)
                if err[f, 0] > 0.1 * cfg.ik_tol:
                    bad = True
                    n_bad += 1
                    pull_lo |= u == 0.0
                    pull_hi |= u == 1.0
            lo[f] += np.where(pull_lo, 0.1 * size, 0.0)
            hi[f] -= np.where(pull_hi, 0.1 * size, 0.0)
        if not bad:
            return lo, hi
        if progress and time.perf_counter() - last >= PROGRESS_EVERY:
            progress(f"  round {r + 1}/20: {n_bad} of {len(grid) * len(lo)} grid points out of reach; box pulled in")
            last = time.perf_counter()
    raise RobotError(f"{ik.robot.source}: the sole workspace box did not become reachable; check the robot's limits")


def ellipsoid_path(p: dict, t: np.ndarray) -> np.ndarray:
    """Sole position on the ellipsoid, paper eq. 2, shape (T, 3) [m]:

        φ_t = −(A_φ/ω_φ) cos(ω_φ t) + A_φ/ω_φ + φ0,
        θ_t = −(A_θ/ω_θ) cos(ω_θ t) + A_θ/ω_θ + θ0,
        x_t = a cos θ_t cos φ_t + x0,   y_t = b cos θ_t sin φ_t + y0,   z_t = c sin θ_t + z0.
    """
    phi = -(p["A_phi"] / p["w_phi"]) * np.cos(p["w_phi"] * t) + p["A_phi"] / p["w_phi"] + p["phi0"]
    theta = -(p["A_theta"] / p["w_theta"]) * np.cos(p["w_theta"] * t) + p["A_theta"] / p["w_theta"] + p["theta0"]
    x = p["a"] * np.cos(theta) * np.cos(phi) + p["x0"]
    y = p["b"] * np.cos(theta) * np.sin(phi) + p["y0"]
    z = p["c"] * np.sin(theta) + p["z0"]
    return np.stack([x, y, z], axis=-1)


def _loguniform(rng, lo_hi):
    return float(np.exp(rng.uniform(np.log(lo_hi[0]), np.log(lo_hi[1]))))


def _draw_ellipsoid(rng, lo, hi, cfg: ExcitationConfig) -> dict:
    half = 0.5 * (hi - lo)
    r = rng.uniform(*cfg.radius_frac, size=3) * half
    centre = rng.uniform(lo + r, hi - r)
    return {"a": r[0], "b": r[1], "c": r[2], "x0": centre[0], "y0": centre[1], "z0": centre[2],
            "A_phi": _loguniform(rng, cfg.peak_rate), "w_phi": _loguniform(rng, cfg.omega),
            "phi0": rng.uniform(0.0, 2 * np.pi),
            "A_theta": _loguniform(rng, cfg.peak_rate), "w_theta": _loguniform(rng, cfg.omega),
            "theta0": rng.uniform(-0.5 * np.pi, 0.5 * np.pi)}


def _upper_body(rng, robot, dofs, t, cfg) -> tuple[np.ndarray, dict]:
    """Multisines for the joints in ``dofs``, shape (T, len(dofs))."""
    lo, hi = finite_limits(robot)
    out, params = np.empty((len(t), len(dofs))), {}
    for i, j in enumerate(dofs):
        c, amp = centre_amplitude(rng, lo[j], hi[j], cfg)
        s, p = multisine(rng, t, amp, cfg)
        out[:, i] = c + s
        params[robot.joint_names[j]] = {"centre": c, **p}
    return out, params


def _sole_tilt(rng, t, cfg) -> tuple[np.ndarray, dict]:
    """Small multisine yaw/pitch/roll of a sole about its level orientation, rotation matrices (T, 3, 3)."""
    from scipy.spatial.transform import Rotation as R

    angles, params = [], {}
    for amp, axis in zip(cfg.tilt, "zyx"):
        s, p = multisine(rng, t, amp, cfg)
        angles.append(s)
        params[axis] = p
    return R.from_euler("ZYX", np.stack(angles, axis=1)).as_matrix(), params


def _ellipsoid(rng, ik: FootIK, ws: Workspace, t, cfg) -> tuple[np.ndarray, np.ndarray, dict]:
    """Sole targets for both feet from eq. 2 plus a tilt: positions (T, F, 3), rotations (T, F, 3, 3)."""
    nf = len(ik.frames)
    pos, rot, params = np.empty((len(t), nf, 3)), np.empty((len(t), nf, 3, 3)), {}
    for f, name in enumerate(ik.frames):
        p = _draw_ellipsoid(rng, ws.lo[f], ws.hi[f], cfg)
        pos[:, f] = ellipsoid_path(p, t)
        if ik.position_only:  # the orientation is no target
            rot[:, f] = ws.level[f]
            params[name] = {"ellipsoid": p}
            continue
        tilt, tp = _sole_tilt(rng, t, cfg)
        rot[:, f] = tilt @ ws.level[f]
        params[name] = {"ellipsoid": p, "tilt": tp}
    return pos, rot, params


def _kick(rng, ik: FootIK, ws: Workspace, t, cfg) -> tuple[np.ndarray, np.ndarray, dict]:
    """One sole at a time makes fast minimum-jerk moves between random workspace points while the other
    holds its place; both soles tilt as in the ellipsoid family."""
    nf = len(ik.frames)
    centre = 0.5 * (ws.lo + ws.hi)
    pos = np.broadcast_to(centre, (len(t), nf, 3)).copy()
    rot = np.empty((len(t), nf, 3, 3))
    for f in range(nf):
        rot[:, f] = ws.level[f] if ik.position_only else _sole_tilt(rng, t, cfg)[0] @ ws.level[f]
    moves, t0, cur = [], 0.2, centre.copy()
    while t0 < t[-1]:
        f = int(rng.integers(nf))
        goal = rng.uniform(ws.lo[f], ws.hi[f])
        dur = rng.uniform(*cfg.kick_time)
        s = np.clip((t - t0) / dur, 0.0, 1.0)[:, None]
        pos[:, f] = np.where((t >= t0)[:, None], cur[f] + min_jerk(s) * (goal - cur[f]), pos[:, f])
        moves.append({"foot": ik.frames[f], "t0": t0, "duration": dur, "goal": goal.tolist()})
        cur[f] = goal
        t0 += dur + rng.uniform(0.0, 0.3)
    return pos, rot, {"moves": moves}


def generate(family: str, robot: Robot, ik: FootIK, ws: Workspace, duration: float, rate_hz: float,
             rng: np.random.Generator, cfg: ExcitationConfig | None = None, progress=None) -> Excitation:
    """Draw one excitation of ``family``; redraws (same generator) until IK and speed checks pass.

    Args:
        family: One of :data:`FAMILIES`.
        robot: The robot (fixed base, with sole sites).
        ik: Foot IK for ``robot``.
        ws: Foot workspace from :func:`foot_workspace`.
        duration: Trajectory length [s].
        rate_hz: Command rate [Hz].
        rng: Random generator (advanced in place).
        cfg: Parameter ranges.
        progress: Optional ``callable(str)`` receiving a line per rejected draw (why, and how long it took).
    """
    cfg = cfg or ExcitationConfig()
    if family not in FAMILIES:
        raise ValueError(f"unknown excitation family {family!r}; choose from {FAMILIES} (joint-space families: "
                         "generate_joint)")
    t = np.arange(int(round(duration * rate_hz))) / rate_hz
    leg = ik.dofs
    rest = np.setdiff1d(np.arange(robot.n_dof), leg)
    for draw in range(cfg.max_draws):
        start = time.perf_counter()
        if family == "chirp":
            q, params = chirp(rng, robot, t, cfg)
            ik_err = 0.0
        else:
            targets = _ellipsoid if family == "ellipsoid" else _kick
            pos, rot, params = targets(rng, ik, ws, t, cfg)
            q_leg, err = ik.solve_path(pos, None if ik.position_only else rot, ws.home)
            ik_err = float(err[:, :, 0].max())
            q = q_leg.copy()
            q[:, rest], params["upper_body"] = _upper_body(rng, robot, rest, t, cfg)
            if ik_err > cfg.ik_tol:
                if progress:
                    progress(f"  {family} draw {draw + 1}/{cfg.max_draws} rejected: IK error {1e3 * ik_err:.2f} mm > "
                             f"{1e3 * cfg.ik_tol:g} mm ({time.perf_counter() - start:.1f} s); drawing again")
                continue
        speed = float(np.abs(np.diff(q, axis=0)).max() * rate_hz)
        lo, hi = finite_limits(robot)
        margin = limit_margin(lo, hi, cfg.limit_margin)
        inside = (q >= lo + 0.5 * margin).all() and (q <= hi - 0.5 * margin).all()
        if speed <= cfg.max_velocity and inside:
            params.update(family=family, draws=draw + 1, ik_max_error_m=ik_err, max_speed=speed)
            return Excitation(family=family, q_cmd=q, params=params)
        if progress:
            why = f"peak {speed:.1f} rad/s > {cfg.max_velocity:g} rad/s" if speed > cfg.max_velocity else \
                "a joint too close to its limit"
            progress(f"  {family} draw {draw + 1}/{cfg.max_draws} rejected: {why} ({time.perf_counter() - start:.1f} s); "
                     "drawing again")
    raise RobotError(f"{robot.source}: no {family} excitation passed the IK ({cfg.ik_tol} m) and speed "
                     f"({cfg.max_velocity} rad/s) checks in {cfg.max_draws} draws; widen the workspace or "
                     "lower peak_rate")


@dataclass
class Plan:
    """A resolved excitation: the mode, and what it needs (foot IK and workspace, or the robot's dynamics)."""

    robot: Robot
    cfg: ExcitationConfig
    """The config, its ``mode`` resolved to ``"foot"`` or ``"joint"`` (and ``frames`` to the IK's)."""
    ik: FootIK | None = None
    """Foot IK (foot mode)."""
    ws: Workspace | None = None
    """Foot workspace (foot mode)."""
    dynamics: JointDynamics | None = None
    """Inverse dynamics of the nominal robot (joint mode)."""

    @property
    def mode(self) -> str:
        return self.cfg.mode

    def families(self, split: str) -> tuple[str, ...]:
        """The families a split draws from, in turn: training ones for train, validation and held-out."""
        if self.mode == "foot":
            return OOD_FAMILIES if split == "ood" else TRAIN_FAMILIES
        return JOINT_OOD_FAMILIES if split == "ood" else JOINT_TRAIN_FAMILIES

    def generate(self, family: str, duration: float, rate_hz: float, rng: np.random.Generator,
                 progress=None) -> Excitation:
        """Draw one excitation (:func:`generate` or :func:`~wresdyn.data.joint_excitation.generate_joint`);
        ``progress``: optional ``callable(str)`` receiving a line per rejected foot-IK draw."""
        if self.mode == "foot":
            return generate(family, self.robot, self.ik, self.ws, duration, rate_hz, rng, self.cfg, progress)
        return generate_joint(family, self.robot, duration, rate_hz, rng, self.cfg, self.dynamics)

    def describe(self, e: Excitation) -> str:
        """The per-trajectory progress figures of one excitation."""
        p = e.params
        if self.mode == "foot":
            return f"IK err {1e3 * p['ik_max_error_m']:.3f} mm  peak {p['max_speed']:4.1f} rad/s"
        return f"peak {p['max_speed']:4.1f} rad/s, {100 * p['peak_effort_fraction']:3.0f} % effort"

    def meta(self) -> dict:
        """What a dataset's meta records of the plan: the foot workspace (foot mode)."""
        if self.mode != "foot":
            return {}
        return {"workspace": {"frames": list(self.ik.frames), "lo_m": self.ws.lo.tolist(), "hi_m": self.ws.hi.tolist()}}


def plan(robot: Robot, cfg: ExcitationConfig | None = None, progress=None) -> Plan:
    """Resolve the excitation mode and prepare it: ``"auto"`` is foot IK when the robot has every frame of
    ``cfg.frames`` as a site (the humanoid's soles), joint space otherwise. The foot mode builds the IK (checking
    the frames' chains, :class:`~wresdyn.data.ik.FootIK`) and samples the workspace.

    Args:
        robot: The robot (fixed base).
        cfg: Parameter ranges, mode and frames.
        progress: Optional ``callable(str)`` receiving progress lines.

    Raises:
        RobotError: one line: an unknown mode, a frame the robot lacks, chains that cannot track the targets.
    """
    cfg = cfg or ExcitationConfig()
    if cfg.mode not in MODES:
        raise RobotError(f"excitation mode must be one of {MODES}, not {cfg.mode!r}")
    mode = cfg.mode
    if mode == "auto":
        mode = "foot" if all(f in robot.frames for f in cfg.frames) else "joint"
    cfg = dataclasses.replace(cfg, mode=mode, frames=tuple(cfg.frames))
    if mode == "joint":
        if progress:
            limit = effort_limit(robot, cfg)
            progress(f"joint-space excitation of {robot.n_dof} joints: speed <= {cfg.joint_max_velocity:g} rad/s, "
                     f"torque <= {cfg.effort_fraction:g} of the effort limit"
                     f"{'' if np.isfinite(limit).all() else ' (joints without a limit unchecked)'}")
        return Plan(robot, cfg, dynamics=JointDynamics(robot))
    ik = FootIK(robot, cfg.frames)
    if progress:
        progress(f"foot IK on {', '.join(ik.frames)} ({'position only' if ik.position_only else 'full pose'}, "
                 f"{len(ik.dofs)} joints): sampling the workspace ({cfg.workspace_samples} configurations)")
    ws = foot_workspace(ik, cfg, progress=progress)
    return Plan(robot, cfg, ik=ik, ws=ws)
