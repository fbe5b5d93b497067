"""Excitation trajectories: the joint commands executed on the (real) robot under PD control.

Training and held-out data use the paper's excitation (Sec. II-A): each sole follows a path on an
ellipsoid (eq. 2) inside that foot's reachable workspace, the leg joints come from the sole IK
(:mod:`wresdyn.data.ik`), and the waist and arm joints, which no foot target moves, get multisines within
their limits, so every joint is excited. eq. 2's angle rate is φ̇ = A_φ sin(ω_φ t): the foot sweeps the
ellipsoid with an instantaneous frequency that rises from 0 to A_φ / 2π and back, a chirp in disguise;
drawing A and ω per trajectory over a wide log-uniform band spreads the command energy from < 0.5 Hz to
several Hz (checked by :func:`band_fraction` and shown by :func:`plot_spectrum`).

Out-of-distribution evaluation uses motion families never seen in training: joint-space ``chirp`` sweeps
and task-space ``kick`` swings (minimum-jerk point-to-point moves of one sole at a time).
Everything is drawn from a seeded :class:`numpy.random.Generator`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..robot.description import Robot, RobotError
from .ik import FootIK

__all__ = ["ExcitationConfig", "Excitation", "Workspace", "FAMILIES", "TRAIN_FAMILIES", "OOD_FAMILIES", "foot_workspace",
           "ellipsoid_path", "generate", "command_spectrum", "band_fraction", "plot_spectrum"]

TRAIN_FAMILIES = ("ellipsoid",)
"""Families used for train and held-out data (the paper's excitation)."""
OOD_FAMILIES = ("chirp", "kick")
"""Families used only for out-of-distribution evaluation."""
FAMILIES = TRAIN_FAMILIES + OOD_FAMILIES


@dataclass(frozen=True)
class ExcitationConfig:
    """Ranges the per-trajectory parameters are drawn from (log-uniform for rates, uniform otherwise)."""

    omega: tuple[float, float] = (0.3, 3.0)
    """eq. 2 angular frequency ω_φ, ω_θ of the angle sweep [rad/s]."""
    peak_rate: tuple[float, float] = (2.0, 30.0)
    """eq. 2 amplitude A_φ, A_θ = peak angle rate [rad/s]; A / 2π is the top sweep frequency [Hz]."""
    radius_frac: tuple[float, float] = (0.35, 1.0)
    """Ellipsoid radii a, b, c as a fraction of the workspace box half-size on that axis [-]."""
    tilt: tuple[float, float, float] = (0.3, 0.2, 0.15)
    """Sole orientation excitation amplitude about z (yaw), y (pitch), x (roll) [rad]; moves hip yaw and ankles."""
    band: tuple[float, float] = (0.1, 8.0)
    """Multisine and chirp frequency band [Hz]."""
    n_sines: int = 6
    """Sines per joint in a multisine."""
    slope: float = 0.3
    """Multisine amplitude ∝ f^-slope: 0 = flat position spectrum, 1 = flat velocity spectrum [-]."""
    amplitude: float = 0.8
    """Largest excursion of a multisine or chirp joint from its centre [rad]."""
    limit_margin: float = 0.05
    """Commands stay this far inside every joint limit [rad]."""
    fade: float = 0.3
    """Multisines and chirps fade in over this time (raised cosine), so every command starts at rest [s]."""
    max_velocity: float = 12.0
    """A drawn trajectory whose command speed exceeds this on any joint is redrawn [rad/s]."""
    ik_tol: float = 1e-3
    """A drawn trajectory whose IK misses any target by more than this is redrawn [m]."""
    max_draws: int = 50
    """Redraws before giving up."""
    kick_time: tuple[float, float] = (0.25, 0.7)
    """Duration of one kick move [s]."""
    workspace_samples: int = 400
    """Random leg configurations sampled (FK, then IK to a level sole) to find each foot's workspace."""
    workspace_quantiles: tuple[float, float] = (0.2, 0.8)
    """Per-axis quantiles of the reachable sole positions that bound the workspace box [-]."""
    min_foot_y: float = 0.05
    """The box of each foot stays this far on its own side of the sagittal plane, so feet never cross [m]."""


@dataclass
class Excitation:
    """One drawn excitation."""

    family: str
    """Motion family, one of :data:`FAMILIES`."""
    q_cmd: np.ndarray
    """Commanded joint positions [rad], shape (T, n_dof); sample k at t = k / rate_hz."""
    params: dict = field(default_factory=dict)
    """Drawn parameters (JSON-serialisable), recorded in the dataset's meta."""


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


def foot_workspace(ik: FootIK, cfg: ExcitationConfig, seed: int = 0) -> Workspace:
    """Sample the reachable workspace of each sole with the sole level: random leg configurations inside the
    limits are moved to the nearest configuration with level soles (orientation-only IK) and their sole
    positions (FK) collected; the box spans the given per-axis quantiles of those positions."""
    rng = np.random.default_rng(seed)
    robot = ik.robot
    q_ref = np.clip(robot.q0, ik.lower, ik.upper)
    _, level = ik.forward(q_ref)
    pts, confs = [], []
    for _ in range(cfg.workspace_samples):
        q = q_ref.copy()
        q[ik.dofs] = rng.uniform(ik.lower[ik.dofs], ik.upper[ik.dofs])
        qs, err = ik.solve(None, level, q)
        if (err[:, 1] < ik.config.rot_tol).all():
            pts.append(ik.forward(qs)[0])
            confs.append(qs)
    if len(pts) < 20:
        raise RobotError(f"{robot.source}: only {len(pts)} of {cfg.workspace_samples} sampled sole positions are "
                         "reachable with a level sole; cannot build the foot workspace")
    pts = np.asarray(pts)
    lo, hi = np.quantile(pts, cfg.workspace_quantiles[0], axis=0), np.quantile(pts, cfg.workspace_quantiles[1], axis=0)
    for f in range(len(lo)):
        side = np.sign(np.median(pts[:, f, 1]))
        if side > 0:
            lo[f, 1] = max(lo[f, 1], cfg.min_foot_y)
        else:
            hi[f, 1] = min(hi[f, 1], -cfg.min_foot_y)
    centre = 0.5 * (lo + hi)
    home = confs[int(np.argmin(np.linalg.norm(pts - centre, axis=2).sum(axis=1)))]
    lo, hi = _shrink_to_reachable(ik, lo, hi, home, level, cfg)
    return Workspace(lo=lo, hi=hi, home=home, level=level)


def _shrink_to_reachable(ik: FootIK, lo, hi, home, level, cfg: ExcitationConfig):
    """The reachable set is curved, so corners of the quantile box can be out of reach: each round, pull in by
    a tenth of the box size every face touched by an unreachable point of a 5x5x5 grid."""
    import itertools

    grid = np.array(list(itertools.product(np.linspace(0.0, 1.0, 5), repeat=3)))
    home_pos, _ = ik.forward(home)
    lo, hi = lo.copy(), hi.copy()
    for _ in range(20):
        bad = False
        for f in range(len(lo)):
            size = hi[f] - lo[f]
            pull_lo, pull_hi = np.zeros(3, dtype=bool), np.zeros(3, dtype=bool)
            for u in grid:
                pos = home_pos.copy()
                pos[f] = lo[f] + u * size
                _, err = ik.solve(pos, level, home)
                if err[f, 0] > 0.1 * cfg.ik_tol:
                    bad = True
                    pull_lo |= u == 0.0
                    pull_hi |= u == 1.0
            lo[f] += np.where(pull_lo, 0.1 * size, 0.0)
            hi[f] -= np.where(pull_hi, 0.1 * size, 0.0)
        if not bad:
            return lo, hi
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


def _fade(t: np.ndarray, cfg: ExcitationConfig) -> np.ndarray:
    """Raised-cosine fade-in, 0 -> 1 over ``cfg.fade`` with zero slope at both ends."""
    s = np.clip(t / cfg.fade, 0.0, 1.0) if cfg.fade > 0 else np.ones_like(t)
    return 0.5 - 0.5 * np.cos(np.pi * s)


def _multisine(rng, t: np.ndarray, amplitude: float, cfg: ExcitationConfig) -> tuple[np.ndarray, dict]:
    """Sum of ``n_sines`` sines, frequencies log-uniform in the band, amplitudes ∝ f^-slope summing to
    ``amplitude`` (a hard bound on the excursion), random phases, faded in."""
    f = np.exp(rng.uniform(np.log(cfg.band[0]), np.log(cfg.band[1]), size=cfg.n_sines))
    a = f ** -cfg.slope
    a *= amplitude / a.sum()
    ph = rng.uniform(0.0, 2 * np.pi, size=cfg.n_sines)
    s = (a[:, None] * np.sin(2 * np.pi * f[:, None] * t + ph[:, None])).sum(axis=0)
    return _fade(t, cfg) * s, {"f": f.tolist(), "a": a.tolist(), "phase": ph.tolist()}


def _centre_amplitude(rng, lo: float, hi: float, cfg: ExcitationConfig) -> tuple[float, float]:
    lo, hi = lo + cfg.limit_margin, hi - cfg.limit_margin
    span = min(hi - lo, 2 * cfg.amplitude)
    c = rng.uniform(lo + 0.5 * span, hi - 0.5 * span) if hi - lo > span else 0.5 * (lo + hi)
    return c, 0.5 * span


def _finite_limits(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
    return lo, np.where(np.isfinite(robot.upper), robot.upper, np.pi)


def _upper_body(rng, robot, dofs, t, cfg) -> tuple[np.ndarray, dict]:
    """Multisines for the joints in ``dofs``, shape (T, len(dofs))."""
    lo, hi = _finite_limits(robot)
    out, params = np.empty((len(t), len(dofs))), {}
    for i, j in enumerate(dofs):
        c, amp = _centre_amplitude(rng, lo[j], hi[j], cfg)
        s, p = _multisine(rng, t, amp, cfg)
        out[:, i] = c + s
        params[robot.joint_names[j]] = {"centre": c, **p}
    return out, params


def _sole_tilt(rng, t, cfg) -> tuple[np.ndarray, dict]:
    """Small multisine yaw/pitch/roll of a sole about its level orientation, rotation matrices (T, 3, 3)."""
    from scipy.spatial.transform import Rotation as R

    angles, params = [], {}
    for amp, axis in zip(cfg.tilt, "zyx"):
        s, p = _multisine(rng, t, amp, cfg)
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
        tilt, tp = _sole_tilt(rng, t, cfg)
        rot[:, f] = tilt @ ws.level[f]
        params[name] = {"ellipsoid": p, "tilt": tp}
    return pos, rot, params


def _min_jerk(s: np.ndarray) -> np.ndarray:
    return 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5


def _kick(rng, ik: FootIK, ws: Workspace, t, cfg) -> tuple[np.ndarray, np.ndarray, dict]:
    """One sole at a time makes fast minimum-jerk moves between random workspace points while the other
    holds its place; both soles tilt as in the ellipsoid family."""
    nf = len(ik.frames)
    centre = 0.5 * (ws.lo + ws.hi)
    pos = np.broadcast_to(centre, (len(t), nf, 3)).copy()
    rot = np.empty((len(t), nf, 3, 3))
    for f in range(nf):
        rot[:, f] = _sole_tilt(rng, t, cfg)[0] @ ws.level[f]
    moves, t0, cur = [], 0.2, centre.copy()
    while t0 < t[-1]:
        f = int(rng.integers(nf))
        goal = rng.uniform(ws.lo[f], ws.hi[f])
        dur = rng.uniform(*cfg.kick_time)
        s = np.clip((t - t0) / dur, 0.0, 1.0)[:, None]
        pos[:, f] = np.where((t >= t0)[:, None], cur[f] + _min_jerk(s) * (goal - cur[f]), pos[:, f])
        moves.append({"foot": ik.frames[f], "t0": t0, "duration": dur, "goal": goal.tolist()})
        cur[f] = goal
        t0 += dur + rng.uniform(0.0, 0.3)
    return pos, rot, {"moves": moves}


def _chirp(rng, robot: Robot, t, cfg) -> tuple[np.ndarray, dict]:
    """Joint-space logarithmic chirps, every joint, from band[0] to band[1] over the trajectory; the amplitude
    falls as 1/f above the frequency where it would exceed ``max_velocity / 2``."""
    lo, hi = _finite_limits(robot)
    f0, f1 = cfg.band
    f = f0 * (f1 / f0) ** (t / t[-1])
    phase = 2 * np.pi * f0 * t[-1] / np.log(f1 / f0) * ((f1 / f0) ** (t / t[-1]) - 1.0)
    q, params = np.empty((len(t), robot.n_dof)), {}
    for j in range(robot.n_dof):
        c, amp = _centre_amplitude(rng, lo[j], hi[j], cfg)
        amp *= rng.uniform(0.5, 1.0)
        a = np.minimum(amp, 0.5 * cfg.max_velocity / (2 * np.pi * f))
        q[:, j] = c + _fade(t, cfg) * a * np.sin(phase)
        params[robot.joint_names[j]] = {"centre": c, "amplitude": amp}
    return q, {"f0": f0, "f1": f1, "joints": params}


def generate(family: str, robot: Robot, ik: FootIK, ws: Workspace, duration: float, rate_hz: float,
             rng: np.random.Generator, cfg: ExcitationConfig | None = None) -> Excitation:
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
    """
    cfg = cfg or ExcitationConfig()
    if family not in FAMILIES:
        raise ValueError(f"unknown excitation family {family!r}; choose from {FAMILIES}")
    t = np.arange(int(round(duration * rate_hz))) / rate_hz
    leg = ik.dofs
    rest = np.setdiff1d(np.arange(robot.n_dof), leg)
    for draw in range(cfg.max_draws):
        if family == "chirp":
            q, params = _chirp(rng, robot, t, cfg)
            ik_err = 0.0
        else:
            targets = _ellipsoid if family == "ellipsoid" else _kick
            pos, rot, params = targets(rng, ik, ws, t, cfg)
            q_leg, err = ik.solve_path(pos, rot, ws.home)
            ik_err = float(err[:, :, 0].max())
            q = q_leg.copy()
            q[:, rest], params["upper_body"] = _upper_body(rng, robot, rest, t, cfg)
            if ik_err > cfg.ik_tol:
                continue
        speed = float(np.abs(np.diff(q, axis=0)).max() * rate_hz)
        lo, hi = _finite_limits(robot)
        inside = (q >= lo + 0.5 * cfg.limit_margin).all() and (q <= hi - 0.5 * cfg.limit_margin).all()
        if speed <= cfg.max_velocity and inside:
            params.update(family=family, draws=draw + 1, ik_max_error_m=ik_err, max_speed=speed)
            return Excitation(family=family, q_cmd=q, params=params)
    raise RobotError(f"{robot.source}: no {family} excitation passed the IK ({cfg.ik_tol} m) and speed "
                     f"({cfg.max_velocity} rad/s) checks in {cfg.max_draws} draws; widen the workspace or "
                     "lower peak_rate")


def command_spectrum(q_cmd: list[np.ndarray] | np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Power spectral density of the commands, Hann-windowed periodogram after removing each joint's mean,
    averaged over trajectories (all of the same length); returns ``(f [Hz], psd [rad^2/Hz])``, psd of shape
    (n_freq, n_dof)."""
    from scipy.signal import periodogram

    q = np.asarray(q_cmd, dtype=np.float64)
    q = q[None] if q.ndim == 2 else q
    f, p = periodogram(q, fs=rate_hz, window="hann", detrend="constant", axis=1)
    return f, p.mean(axis=0)


def band_fraction(f: np.ndarray, psd: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Fraction of each joint's command energy in ``lo <= f < hi`` [Hz], shape (n_dof,)."""
    total = psd.sum(axis=0)
    band = psd[(f >= lo) & (f < hi)].sum(axis=0)
    return band / np.where(total > 0, total, 1.0)


def plot_spectrum(groups: dict[str, list[np.ndarray]], rate_hz: float, path, joint_names: list[str]) -> None:
    """Save a log-log plot of the command PSD (mean over joints) per group of trajectories, with the per-joint
    spread shaded, to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2), constrained_layout=True)
    f_min = rate_hz / 2
    for name, qs in groups.items():
        if not qs:
            continue
        f, p = command_spectrum(qs, rate_hz)
        keep = f > 0
        f_min = min(f_min, f[keep][0])
        line, = ax.loglog(f[keep], p[keep].mean(axis=1), label=f"{name} (mean of {len(joint_names)} joints)")
        ax.fill_between(f[keep], np.quantile(p[keep], 0.1, axis=1), np.quantile(p[keep], 0.9, axis=1),
                        color=line.get_color(), alpha=0.15, linewidth=0)
    for x in (0.5, 2.0):  # the bands the frequency-content check compares
        ax.axvline(x, color="0.6", linestyle=":", linewidth=1)
        ax.text(x, 1.0, f" {x:g} Hz", transform=ax.get_xaxis_transform(), va="top", fontsize=8, color="0.4")
    ax.set_xlim(f_min, min(50.0, rate_hz / 2))
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("command PSD [rad²/Hz]")
    ax.set_title("Excitation command spectrum (shaded: 10-90 % of joints)")
    ax.legend(loc="lower left", fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)
