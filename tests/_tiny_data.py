"""Tiny recorded datasets for learner tests: a perturbed MuJoCo robot plays the part of the real one.

The "real" robot is :func:`wresdyn.robot.mujoco_model.build_mujoco` with extra joint friction and damping and
scaled PD gains (the sim-to-real gap a residual has to explain); it is driven open-loop by a smooth
multisine command and its joint states are recorded every step, like a robot logging at ``rate_hz``.

The shipped real robot (:mod:`wresdyn.data.real_robot`) has more effects (delay, saturation, noise); this one is
small and has a closed-form residual (``tests/test_evaluate.py::Oracle``), which the learner tests need.
"""

from __future__ import annotations

import numpy as np

from wresdyn.data.dataset import Dataset, Trajectory

DEFAULT_MISMATCH = {"friction_frac": 0.02, "damping_frac": 0.01, "kp_scale": 0.9, "kd_scale": 1.2}
"""Real-robot perturbation: dry friction and viscous damping as fractions of each joint's effort limit
[N*m, N*m*s/rad], and PD gain scale factors."""


def real_mujoco(robot, dt: float, mismatch: dict):
    """The "real" robot: the MuJoCo model of ``robot`` with ``mismatch`` applied."""
    from wresdyn.robot.mujoco_model import build_mujoco

    m = build_mujoco(robot, dt)
    effort = np.where(np.isfinite(robot.effort), robot.effort, 50.0)
    m.dof_frictionloss[:] = mismatch["friction_frac"] * effort
    m.dof_damping[:] = mismatch["damping_frac"] * effort
    kp, kd = robot.kp * mismatch["kp_scale"], robot.kd * mismatch["kd_scale"]
    # position actuator: force = kp * ctrl - kp * q - kv * qd
    m.actuator_gainprm[:, 0] = kp
    m.actuator_biasprm[:, 1] = -kp
    m.actuator_biasprm[:, 2] = -kd
    return m


def multisine(robot, seconds: float, dt: float, freq: tuple[float, float], amplitude: float, rng) -> np.ndarray:
    """Smooth multisine command about mid-range [rad], shape (T, n), faded in over the first 0.2 s."""
    t = np.arange(int(round(seconds / dt)))[:, None] * dt
    lo = np.where(np.isfinite(robot.lower), robot.lower, -0.5)
    hi = np.where(np.isfinite(robot.upper), robot.upper, 0.5)
    mid, half = (lo + hi) / 2.0, np.minimum((hi - lo) / 2.0, 1.0)
    f = rng.uniform(*freq, size=(3, robot.n_dof))
    ph = rng.uniform(0.0, 2 * np.pi, size=(3, robot.n_dof))
    wave = sum(np.sin(2 * np.pi * f[i] * t + ph[i]) - np.sin(ph[i]) for i in range(3)) / 3.0
    fade = np.clip(t / 0.2, 0.0, 1.0)
    return mid + amplitude * half * fade * wave


def record(robot, q_cmd: np.ndarray, dt: float, mismatch: dict, name: str, split: str):
    """Play ``q_cmd`` on the "real" robot from rest at ``q_cmd[0]`` and record a :class:`Trajectory`."""
    from wresdyn.robot.mujoco_model import mujoco_replay

    q, qd = mujoco_replay(real_mujoco(robot, dt, mismatch), q_cmd[:-1], q_cmd[0])
    qdd = np.gradient(qd, dt, axis=0)
    t = np.arange(len(q_cmd)) * dt
    return Trajectory(name=name, split=split, t=t, q=q, qd=qd, qdd=qdd, q_cmd=q_cmd.copy())


def make_dataset(robot, seconds: float = 0.2, counts=(2, 1, 1), rate_hz: float = 500.0, seed: int = 0,
                 mismatch: dict | None = None, amplitude: float = 0.3) -> Dataset:
    """A dataset of ``counts`` = (train, heldout, ood) trajectories; OOD uses faster, larger commands."""
    mismatch = dict(DEFAULT_MISMATCH if mismatch is None else mismatch)
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate_hz
    trajs = []
    for split, count in zip(("train", "heldout", "ood"), counts):
        freq, amp = ((2.0, 4.0), 1.5 * amplitude) if split == "ood" else ((0.3, 2.0), amplitude)
        for i in range(count):
            cmd = multisine(robot, seconds, dt, freq, amp, rng)
            trajs.append(record(robot, cmd, dt, mismatch, f"{split}_{i}", split))
    return Dataset(joint_names=list(robot.joint_names), rate_hz=rate_hz, trajectories=trajs,
                   robot_file=str(robot.source), robot_sha256=robot.source_sha256, mismatch=mismatch, seed=seed,
                   meta={"generator": "tests/_tiny_data.py"})
