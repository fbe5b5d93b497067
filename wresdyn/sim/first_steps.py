"""Does the model survive its first steps? A cheap check before a long job.

A gains config with an absurd stiffness, or a file with a tiny mass or inertia behind a stiff drive, makes the PD
step unstable: the simulation blows up within milliseconds, but ``collect`` would find out only at the end of a
recorded trajectory and ``fit`` only inside its optimisation. Both commands therefore simulate
:data:`SECONDS` of one robot first and refuse a model whose joint speed becomes non-finite or exceeds
:attr:`~wresdyn.sim.simulator.DivergenceLimits.max_qd` (the limit the learners reset a world at), naming the worst
joint: :func:`check_mujoco` for the MuJoCo "real robot" of ``collect`` (mismatch, delay and servo law included),
from rest at the neutral pose under a small commanded step (:func:`probe_command`: the drives act even where gravity
does not load a joint); :func:`check_newton` for the Newton replay of ``fit``, from the data's first sample under
its own commands. Both cost a few milliseconds on a compiled model.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from ..errors import SimulationDiverged
from ..robot.servo import GoalProfile
from .simulator import DivergenceLimits, Simulator

__all__ = ["SECONDS", "check_mujoco", "check_newton", "probe_command"]

SECONDS = 0.1
"""Simulated time of the check [s]: an unstable PD step grows by a large factor per step, so it shows within tens
of steps; a stable robot's step response stays far below the speed limit."""
STEP = (0.05, 0.005)
"""Size of the commanded step away from the start pose: revolute [rad], prismatic [m]; small enough for any robot's
PD to follow calmly."""


def probe_command(robot, q_start: np.ndarray, n: int) -> np.ndarray:
    """The check's commands [rad or m], shape (n, n_dof): ``q_start`` for the first sample, then a small step
    (:data:`STEP`) towards the middle of each joint's range."""
    q_start = np.asarray(q_start, dtype=np.float64)
    size = np.where(robot.is_prismatic(), STEP[1], STEP[0])
    limited = np.isfinite(robot.lower) & np.isfinite(robot.upper)
    mid = np.where(limited, 0.5 * (np.where(limited, robot.lower, 0.0) + np.where(limited, robot.upper, 0.0)), np.inf)
    target = np.clip(q_start + np.where(mid >= q_start, size, -size), robot.lower, robot.upper)
    cmd = np.tile(target, (max(n, 2), 1))
    cmd[0] = q_start
    return cmd


def _refuse(robot, where: str, peak: np.ndarray, t: float, worst: int | None = None) -> None:
    """Raise :class:`SimulationDiverged` naming the worst joint: the fastest, or ``worst`` where the simulator itself
    named the DoF whose acceleration blew up."""
    j = int(np.argmax(peak)) if worst is None else worst
    if worst is not None:
        what = "a non-finite or huge acceleration"
    else:
        what = "a non-finite speed" if not np.isfinite(peak[j]) else f"|qd| {peak[j]:.3g} rad/s"
    raise SimulationDiverged(
        f"{robot.source.name}: the {where} diverges within {t:.3f} s of its start pose: joint {robot.joint_names[j]} "
        f"reaches {what} (limit {DivergenceLimits.max_qd:g} rad/s); lower its kp/kd in the gains config (--gains) "
        "or check the masses, inertias and armature of the links it drives")


def _peak(peak: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """Running max of |qd| per joint, a non-finite speed counting as infinite."""
    a = np.abs(np.asarray(qd, dtype=np.float64))
    return np.maximum(peak, np.where(np.isfinite(a), a, np.inf))


def check_mujoco(real, q_start: np.ndarray | None = None, seconds: float = SECONDS) -> None:
    """Run the MuJoCo "real robot" (:class:`~wresdyn.data.real_robot.RealRobot`, fixed base) from rest at
    ``q_start`` (default: the robot's neutral pose) under :func:`probe_command`, as :meth:`RealRobot.record` runs it
    (delay line, servo law).

    Raises:
        SimulationDiverged: a non-finite or runaway joint speed, or MuJoCo's own bad-state warning (it resets a
            diverged simulation); the message names the worst joint.
    """
    import mujoco

    robot, m = real.robot, real.model
    n = robot.n_dof
    q_start = robot.q0 if q_start is None else np.asarray(q_start, dtype=np.float64)
    cmd = probe_command(robot, q_start, int(round(seconds * real.rate_hz)))
    d = mujoco.MjData(m)
    d.qpos[:n], d.qvel[:] = q_start, 0.0
    fifo = deque([cmd[0]] * real.n_delay)
    servo = real._servo
    profile = None if servo is None else GoalProfile(servo["goal_accel"], real.substep, cmd[0])
    bad = [int(w) for w in (mujoco.mjtWarning.mjWARN_BADQACC, mujoco.mjtWarning.mjWARN_BADQVEL,
                            mujoco.mjtWarning.mjWARN_BADQPOS)]
    peak = np.zeros(n)
    for k in range(len(cmd)):
        for _ in range(real.n_sub):
            fifo.append(cmd[k])
            d.ctrl[:] = fifo.popleft() if profile is None else real._servo_ctrl(d, fifo.popleft(), profile)
            mujoco.mj_step(m, d)
            peak = _peak(peak, d.qvel[:n])
            flagged = any(d.warning[w].number > 0 for w in bad)
            if flagged or peak.max() > DivergenceLimits.max_qd:
                # MuJoCo has reset a diverged state (so the speeds may look calm): its warning names the DoF
                info = int(d.warning[bad[0]].lastinfo) if d.warning[bad[0]].number > 0 else -1
                worst = info if flagged and not peak.max() > DivergenceLimits.max_qd and 0 <= info < n else None
                _refuse(robot, "MuJoCo real robot", peak, (k + 1) / real.rate_hz, worst)


def check_newton(robot, rate_hz: float, q_start: np.ndarray, qd_start: np.ndarray | None = None,
                 q_cmd: np.ndarray | None = None, *, solver: str = "auto", device: str | None = "cpu",
                 physics=None, friction_kappa=None, seconds: float = SECONDS) -> None:
    """Run one Newton world (:class:`~wresdyn.sim.Simulator`, the solver and device a fit uses) from ``q_start``,
    ``qd_start`` (default: rest) under ``q_cmd`` (the recorded commands, shape (T, n_dof); default:
    :func:`probe_command`), for ``seconds`` at ``rate_hz``.

    Args:
        physics: :class:`~wresdyn.sim.physics.PhysicalParams` to run on instead of the file's (a fit's ``--physics``).

    Raises:
        SimulationDiverged: a non-finite or runaway joint speed; the message names the worst joint.
    """
    import torch

    n_steps = max(int(round(seconds * rate_hz)), 2)
    q_start = np.asarray(q_start, dtype=np.float64)
    cmd = probe_command(robot, q_start, n_steps) if q_cmd is None else np.asarray(q_cmd, dtype=np.float64)[:n_steps]
    sim = Simulator(robot, 1, 1.0 / rate_hz, solver=solver, device=device, friction_kappa=friction_kappa)
    if physics is not None:
        sim.set_physics(physics)
    f32 = dict(dtype=torch.float32, device=sim.device)
    qd0 = np.zeros_like(q_start) if qd_start is None else qd_start
    sim.set_state(None, torch.as_tensor(q_start[None], **f32), torch.as_tensor(np.asarray(qd0)[None], **f32))
    target = torch.as_tensor(cmd, **f32)
    peak = np.zeros(robot.n_dof)
    for k in range(len(cmd)):
        _, qd = sim.step(target[k:k + 1])
        peak = _peak(peak, qd[0].cpu().numpy())
        if peak.max() > DivergenceLimits.max_qd:
            _refuse(robot, f"Newton replay ({sim.solver_kind})", peak, (k + 1) / rate_hz)
