"""What both excitation modes share: the config, one drawn excitation, the family names, and the command
signal shapes (raised-cosine fade-in, multisine, logarithmic chirp, minimum-jerk move) that the foot mode
(:mod:`wresdyn.data.excitation`) and the joint-space mode (:mod:`wresdyn.data.joint_excitation`) are built from.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..choices import ExcitationMode, choices
from ..robot.description import Robot
from .ik import SOLES

__all__ = ["ExcitationConfig", "Excitation", "FAMILIES", "TRAIN_FAMILIES", "OOD_FAMILIES", "JOINT_FAMILIES",
           "JOINT_TRAIN_FAMILIES", "JOINT_OOD_FAMILIES", "MODES", "fade", "multisine", "centre_amplitude",
           "limit_margin", "finite_limits", "min_jerk", "chirp"]

TRAIN_FAMILIES = ("ellipsoid",)
"""Families used for train and held-out data (the paper's excitation)."""
OOD_FAMILIES = ("chirp", "kick")
"""Families used only for out-of-distribution evaluation."""
FAMILIES = TRAIN_FAMILIES + OOD_FAMILIES
"""Families of the foot (IK) mode."""
JOINT_TRAIN_FAMILIES = ("multisine",)
"""Joint-space mode: families for train, validation and held-out data."""
JOINT_OOD_FAMILIES = ("chirp", "steps")
"""Joint-space mode: families for out-of-distribution data."""
JOINT_FAMILIES = JOINT_TRAIN_FAMILIES + JOINT_OOD_FAMILIES
MODES = choices(ExcitationMode)
"""Excitation modes: foot IK targets, joint space, or foot when the robot has all the frames."""


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
    """Commands stay this far inside every joint limit [rad], a narrow joint a quarter of its range
    (:func:`limit_margin`)."""
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
    """The box of each foot stays this far on its own side of the sagittal plane, so feet never cross [m]
    (with two or more frames, each on a clear side)."""
    mode: ExcitationMode = "auto"
    """One of :data:`MODES`; :func:`plan` resolves ``"auto"`` (and records the resolved mode)."""
    frames: tuple[str, ...] = SOLES
    """IK frames of the foot mode (sites or bodies), one ellipsoid path each."""
    joint_max_velocity: float = 5.0
    """Joint-space mode: command speed bound [rad/s] (about an STS3215 servo's no-load speed, 5.4 rad/s at
    7.4 V; the foot mode keeps ``max_velocity``)."""
    effort_fraction: float = 0.5
    """Joint-space mode: the torque a command needs on the nominal robot (inverse dynamics) stays under this
    fraction of each joint's effort limit [-]; joints without a limit are not checked."""


@dataclass
class Excitation:
    """One drawn excitation."""

    family: str
    """Motion family, one of :data:`FAMILIES`."""
    q_cmd: np.ndarray
    """Commanded joint positions [rad], shape (T, n_dof); sample k at t = k / rate_hz."""
    params: dict = field(default_factory=dict)
    """Drawn parameters (JSON-serialisable), recorded in the dataset's meta."""


def fade(t: np.ndarray, cfg: ExcitationConfig) -> np.ndarray:
    """Raised-cosine fade-in, 0 -> 1 over ``cfg.fade`` with zero slope at both ends."""
    s = np.clip(t / cfg.fade, 0.0, 1.0) if cfg.fade > 0 else np.ones_like(t)
    return 0.5 - 0.5 * np.cos(np.pi * s)


def multisine(rng, t: np.ndarray, amplitude: float, cfg: ExcitationConfig) -> tuple[np.ndarray, dict]:
    """Sum of ``n_sines`` sines, frequencies log-uniform in the band, amplitudes ∝ f^-slope summing to
    ``amplitude`` (a hard bound on the excursion), random phases, faded in."""
    f = np.exp(rng.uniform(np.log(cfg.band[0]), np.log(cfg.band[1]), size=cfg.n_sines))
    a = f ** -cfg.slope
    a *= amplitude / a.sum()
    ph = rng.uniform(0.0, 2 * np.pi, size=cfg.n_sines)
    s = (a[:, None] * np.sin(2 * np.pi * f[:, None] * t + ph[:, None])).sum(axis=0)
    return fade(t, cfg) * s, {"f": f.tolist(), "a": a.tolist(), "phase": ph.tolist()}


def limit_margin(lo, hi, margin: float):
    """How far commands stay inside the limits ``lo``, ``hi`` (scalars or arrays): ``margin``, but at most a quarter
    of the range, so a joint narrower than twice the margin (a Panda finger's 0.04 m against 0.05) keeps half its
    range to move in rather than none."""
    return np.minimum(margin, 0.25 * (np.asarray(hi) - np.asarray(lo)))


def centre_amplitude(rng, lo: float, hi: float, cfg: ExcitationConfig) -> tuple[float, float]:
    m = limit_margin(lo, hi, cfg.limit_margin)
    lo, hi = lo + m, hi - m
    span = min(hi - lo, 2 * cfg.amplitude)
    c = rng.uniform(lo + 0.5 * span, hi - 0.5 * span) if hi - lo > span else 0.5 * (lo + hi)
    return c, 0.5 * span


def finite_limits(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    lo = np.where(np.isfinite(robot.lower), robot.lower, -np.pi)
    return lo, np.where(np.isfinite(robot.upper), robot.upper, np.pi)


def min_jerk(s: np.ndarray) -> np.ndarray:
    return 10 * s ** 3 - 15 * s ** 4 + 6 * s ** 5


def chirp(rng, robot: Robot, t, cfg, vmax: float | None = None, amax: np.ndarray | None = None
           ) -> tuple[np.ndarray, dict]:
    """Joint-space logarithmic chirps, every joint, from band[0] to band[1] over the trajectory; the amplitude
    falls as 1/f above the frequency where it would exceed ``vmax / 2`` (default ``max_velocity``) [rad/s] and,
    with ``amax`` (per joint [rad/s^2], shape (n_dof,)), as 1/f^2 above where the acceleration would exceed
    ``amax / 2``, the caps then blended by a smooth minimum."""
    vmax = cfg.max_velocity if vmax is None else vmax
    lo, hi = finite_limits(robot)
    f0, f1 = cfg.band
    f = f0 * (f1 / f0) ** (t / t[-1])
    phase = 2 * np.pi * f0 * t[-1] / np.log(f1 / f0) * ((f1 / f0) ** (t / t[-1]) - 1.0)
    q, params = np.empty((len(t), robot.n_dof)), {}
    for j in range(robot.n_dof):
        c, amp = centre_amplitude(rng, lo[j], hi[j], cfg)
        amp *= rng.uniform(0.5, 1.0)
        if amax is None:
            a = np.minimum(amp, 0.5 * vmax / (2 * np.pi * f))
        else:  # a smooth minimum: a kink in a(t) would be a step in the speed and a spike in the torque
            w = 2 * np.pi * f
            a = (amp ** -2 + (0.5 * vmax / w) ** -2 + (0.5 * amax[j] / w ** 2) ** -2) ** -0.5
        q[:, j] = c + fade(t, cfg) * a * np.sin(phase)
        params[robot.joint_names[j]] = {"centre": c, "amplitude": amp}
    return q, {"f0": f0, "f1": f1, "joints": params}


