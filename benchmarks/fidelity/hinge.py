"""The one-hinge robot and the two rollouts the friction benchmarks compare (SolverReplay against MuJoCo C).

The same cases as ``tests/sim/test_friction.py``, kept here so the benchmarks import nothing from ``tests/``.
"""

from __future__ import annotations

from pathlib import Path

import mujoco
import numpy as np
import warp as wp

from wresdyn.robot.description import load_robot
from wresdyn.robot.mujoco_model import build_mujoco
from wresdyn.sim.solver_replay import SolverReplay

DT = 0.002
"""Step of both simulators [s]."""

HINGE_URDF = """<?xml version="1.0"?>
<robot name="hinge">
  <link name="base"><inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/>
    </inertial></link>
  <link name="arm"><inertial><origin xyz="0.1 0 0"/><mass value="1.0"/>
    <inertia ixx="0.002" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="hinge" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 1"/><axis xyz="0 0 1"/>
    <limit lower="-100" upper="100" effort="100" velocity="100"/></joint>
</robot>
"""
"""One hinge about the vertical (gravity exerts no torque): H = 0.01 + 1.0 * 0.1^2 + armature 0.01 = 0.03 kg m^2."""

MU = 1.0
"""Friction torque of the hinge [N m]."""


def make_hinge(folder):
    """The hinge robot (no drive, friction ``MU``, armature 0.01), its URDF written into ``folder``."""
    path = Path(folder) / "hinge.urdf"
    path.write_text(HINGE_URDF)
    return load_robot(path, gains={"joint": [{"match": "*", "kp": 0.0, "kd": 0.0, "friction": MU, "armature": 0.01}]})


def newton_rollout(robot, q0, cmd, joint_f=None, dtype=wp.float32, device="cpu", **kw):
    """SolverReplay from ``q0`` at rest under the PD targets ``cmd`` (T, n) [rad] and the torques ``joint_f`` (T, n)
    [N m]: q, qd of shape (T + 1, n)."""
    solver = SolverReplay(robot.build_model(1, device), dtype=dtype, **kw)
    t_len, n = cmd.shape
    npt = np.float64 if dtype == wp.float64 else np.float32
    q, qd = np.zeros((t_len + 1, 1, n), npt), np.zeros((t_len + 1, 1, n), npt)
    q[0, 0] = q0
    qa, qda = wp.array(q, dtype=dtype, device=device), wp.array(qd, dtype=dtype, device=device)
    f = None if joint_f is None else wp.array(joint_f[:, None].astype(npt), dtype=dtype, device=device)
    solver.rollout(qa, qda, wp.array(cmd[:, None].astype(npt), dtype=dtype, device=device), DT, joint_f=f)
    return qa.numpy()[:, 0], qda.numpy()[:, 0]


def mujoco_rollout(robot, q0, cmd, joint_f=None):
    """The same rollout in MuJoCo C (implicitfast): q, qd of shape (T + 1, n)."""
    m = build_mujoco(robot, DT, "implicitfast")
    d = mujoco.MjData(m)
    d.qpos[:] = q0
    q, qd = [d.qpos.copy()], [d.qvel.copy()]
    for k in range(len(cmd)):
        d.ctrl[:] = cmd[k]
        if joint_f is not None:
            d.qfrc_applied[:] = joint_f[k]
        mujoco.mj_step(m, d)
        q.append(d.qpos.copy())
        qd.append(d.qvel.copy())
    return np.array(q), np.array(qd)
