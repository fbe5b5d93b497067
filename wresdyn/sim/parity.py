"""Checks that Newton and MuJoCo see the same robot: a joint table and a short PD-replay comparison."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot.description import Robot
from ..robot.mujoco_model import build_mujoco, mujoco_replay
from .rollout import replay
from .solvers import resolve_solver

__all__ = ["joint_table", "multisine_command", "PdAgreement", "pd_agreement"]


def joint_table(robot: Robot) -> str:
    """A fixed-width table of the actuated joints: name, limits, gains, effort, armature, friction."""
    unit = lambda i: "m" if robot.is_prismatic()[i] else "rad"  # noqa: E731
    head = f"{'#':>3} {'joint':<22} {'lower':>8} {'upper':>8} {'unit':>4} {'kp':>9} {'kd':>7} {'effort':>8} {'armature':>9} {'friction':>8}"
    rows = [head, "-" * len(head)]
    for i, name in enumerate(robot.joint_names):
        rows.append(
            f"{i:>3} {name:<22} {robot.lower[i]:>8.3f} {robot.upper[i]:>8.3f} {unit(i):>4} {robot.kp[i]:>9.2f} "
            f"{robot.kd[i]:>7.2f} {robot.effort[i]:>8.1f} {robot.armature[i]:>9.4f} {robot.friction[i]:>8.3f}"
        )
    return "\n".join(rows)


def multisine_command(robot: Robot, seconds: float, dt: float, amplitude: float = 0.2, seed: int = 0) -> np.ndarray:
    """A smooth multisine joint command inside the limits, for checks [rad], shape (T, n_dof).

    Each joint oscillates about the middle of its range (or 0 if unlimited) with ``amplitude`` of its
    half-range (at most 0.5 rad), as a sum of three sines between 0.3 and 3 Hz with random phases.
    """
    rng = np.random.default_rng(seed)
    t = np.arange(int(round(seconds / dt)))[:, None] * dt
    lo = np.where(np.isfinite(robot.lower), robot.lower, -0.5)
    hi = np.where(np.isfinite(robot.upper), robot.upper, 0.5)
    mid, half = (lo + hi) / 2.0, np.minimum((hi - lo) / 2.0, 2.5)
    freqs = rng.uniform(0.3, 3.0, size=(3, robot.n_dof))
    phase = rng.uniform(0.0, 2.0 * np.pi, size=(3, robot.n_dof))
    wave = sum(np.sin(2.0 * np.pi * freqs[i] * t + phase[i]) for i in range(3)) / 3.0
    return mid + amplitude * half * wave


@dataclass(frozen=True)
class PdAgreement:
    """Newton vs MuJoCo C on the same PD replay."""

    max_abs: float
    """max |q_newton - q_mujoco| over joints and time [rad or m]."""
    mean_abs: float
    """mean |q_newton - q_mujoco| [rad or m]."""
    tracking: float
    """mean |q_mujoco - q_cmd|, how hard the command was to follow [rad or m]."""
    integrator: str
    """MuJoCo integrator used."""
    solver: str
    """Newton solver used."""


def pd_agreement(robot: Robot, seconds: float = 2.0, dt: float = 0.002, integrator: str | None = None,
                 solver: str = "auto") -> PdAgreement:
    """Replay one multisine command in Newton and in MuJoCo C from the same start and compare joint positions.

    ``integrator=None`` takes the MuJoCo integrator of the same scheme as the Newton solver, so the two agree to
    float32 round-off: ``"Euler"`` (semi-implicit Euler, explicit PD) for Featherstone, ``"implicitfast"``
    (implicit drive damping) for SolverReplay and SolverMuJoCo. Across schemes they differ by O(dt).
    """

    robot.check_gains()
    if integrator is None:
        integrator = "Euler" if resolve_solver(robot, dt, solver) == "featherstone" else "implicitfast"
    cmd = multisine_command(robot, seconds, dt)
    q_newton, _ = replay(robot, cmd, cmd[0], dt=dt, solver=solver)
    q_mj, _ = mujoco_replay(build_mujoco(robot, dt, integrator), cmd, cmd[0])
    err = np.abs(q_newton - q_mj)
    chosen = resolve_solver(robot, dt, solver)
    return PdAgreement(float(err.max()), float(err.mean()), float(np.abs(q_mj[1:] - cmd).mean()), integrator, chosen)
