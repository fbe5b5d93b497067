"""SolverReplay's dry friction against MuJoCo C ``frictionloss`` and against its own closed forms.

The model (see :mod:`wresdyn.sim.solver_replay.solver`): after the frictionless implicit step, Gauss-Seidel sweeps
solve ``min_v 1/2 (v - v*)^T (H / dt) (v - v*) + sum_i g_i(v_i)``. By default ``g_i`` is MuJoCo's default soft
``frictionloss`` written per DoF (its regulariser scaled by the DoF's effective inertia at the reference pose, its
reference acceleration ``-b qd``); ``friction_kappa`` selects the older law, a saturated damper
``tau = -clamp(kappa H_ii v, -mu, mu)`` on the new velocity (``kappa = inf``: hard Coulomb friction).
"""

import math
from pathlib import Path

import mujoco
import numpy as np
import pytest
import warp as wp

from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.robot.mujoco_model import build_mujoco
from wresdyn.sim.parity import multisine_command
from wresdyn.sim.solver_replay import FRICTION_KAPPA, SolverReplay

DT = 0.002

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

H = 0.03
"""The hinge's inertia about its axis, armature included [kg m^2]."""

MU = 1.0
"""Friction torque of the hinge [N m]."""


def make_hinge(folder):
    """The hinge robot (no drive, friction ``MU``, armature 0.01), its URDF written into ``folder``."""
    path = Path(folder) / "hinge.urdf"
    path.write_text(HINGE_URDF)
    return load_robot(path, gains={"joint": [{"match": "*", "kp": 0.0, "kd": 0.0, "friction": MU, "armature": 0.01}]})


@pytest.fixture(scope="module")
def hinge(tmp_path_factory):
    return make_hinge(tmp_path_factory.mktemp("hinge"))


@pytest.fixture(scope="module")
def tri_robot(tmp_path_factory):
    from test_solver_replay import TRI_URDF

    path = tmp_path_factory.mktemp("tri") / "tri.urdf"
    path.write_text(TRI_URDF)
    return load_robot(path, gains={"joint": [{"match": "*", "kp": 30.0, "kd": 1.0, "armature": 0.01}]})


def newton_rollout(robot, q0, cmd, joint_f=None, dtype=wp.float32, device="cpu", **kw):
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


# ---------------------------------------------------------------- one hinge against MuJoCo


@pytest.mark.parametrize("ratio", [0.5, 0.9])
def test_hinge_creeps_like_mujoco_below_the_threshold(hinge, ratio):
    """A constant torque below mu from rest, 1 s: MuJoCo's soft frictionloss creeps at (1 - d0) tau / (d0 b H)."""
    tau, cmd = np.full((500, 1), ratio * MU), np.zeros((500, 1))
    mq, _ = mujoco_rollout(hinge, np.zeros(1), cmd, tau)
    q, qd = newton_rollout(hinge, np.zeros(1), cmd, tau)
    creep = ratio * MU / (FRICTION_KAPPA * H)  # (1 - d0) tau / (d0 b H) = tau / (kappa H): the steady creep
    assert qd[-1, 0] == pytest.approx(creep, rel=1e-4)
    # the soft law relaxes to it as MuJoCo does (over 1 / (d0 b) = 10 ms): measured 7e-8 and 1.2e-7 rad apart
    assert np.abs(q[:, 0] - mq[:, 0]).max() < 1e-6
    # the older damper law reaches the same creep velocity but relaxes in ~1 ms: measured 0.8 % ahead after 1 s
    q_damp, _ = newton_rollout(hinge, np.zeros(1), cmd, tau, friction_kappa=FRICTION_KAPPA)
    assert q_damp[-1, 0] == pytest.approx(mq[-1, 0], rel=0.015) and abs(q_damp[-1, 0] - mq[-1, 0]) > 1e-5
    # hard Coulomb friction holds the joint exactly
    q_hard, qd_hard = newton_rollout(hinge, np.zeros(1), cmd, tau, friction_kappa=math.inf)
    assert not q_hard.any() and not qd_hard.any()


@pytest.mark.parametrize("ratio", [1.5, 3.0])
def test_hinge_slides_like_mujoco_above_the_threshold(hinge, ratio):
    """Above mu it accelerates at (tau - mu) / H from the first step on, in MuJoCo and in hard Coulomb."""
    tau, cmd = np.full((500, 1), ratio * MU), np.zeros((500, 1))
    mq, _ = mujoco_rollout(hinge, np.zeros(1), cmd, tau)
    q_hard, _ = newton_rollout(hinge, np.zeros(1), cmd, tau, dtype=wp.float64, friction_kappa=math.inf)
    # semi-implicit Euler of q'' = (tau - mu) / H: q_k = a dt^2 k (k + 1) / 2. float64 kernels, but Newton
    # stores the inertias in float32 (relative 6e-8 each; measured 5e-9 on q); MuJoCo: 7e-9
    exact = (ratio - 1.0) * MU / H * DT * DT * np.arange(501) * np.arange(1, 502) / 2.0
    assert np.abs(q_hard[:, 0] - exact).max() < 1e-7 * exact[-1]
    assert np.abs(mq[:, 0] - exact).max() < 1e-7 * exact[-1]
    # the soft law saturates in its first step, as MuJoCo does (measured 2.6e-5 and 1.0e-4 rad apart: float32
    # round-off of q up to 33 rad); the older damper needs a few steps (1.5 mu: 1.2e-3 rad behind)
    q, _ = newton_rollout(hinge, np.zeros(1), cmd, tau)
    assert np.abs(q[:, 0] - mq[:, 0]).max() < 3e-4


# ---------------------------------------------------------------- coupled joints, exact sticking


def test_hard_coulomb_holds_a_coupled_joint_exactly(tri_robot):
    """A joint whose mu exceeds every torque it feels stays exactly still while the others swing (the friction
    solve is exact per coordinate; coupling through H goes through the sweeps)."""
    mu = np.array([0.0, 1e3, 0.0])  # the elbow is held; it couples to the shoulder and the slider
    robot = load_robot(tri_robot.source, gains={"joint": [
        {"match": name, "kp": 30.0, "kd": 1.0, "armature": 0.01, "friction": float(m)}
        for name, m in zip(tri_robot.joint_names, mu)]})
    cmd = np.tile([0.8, -0.5, 0.1], (300, 1))
    q, qd = newton_rollout(robot, np.array([0.1, 0.3, 0.0]), cmd, friction_kappa=math.inf)
    assert np.ptp(q[:, 0]) > 0.5 and np.ptp(q[:, 2]) > 0.05  # the others move
    assert (q[:, 1] == np.float32(0.3)).all() and not qd[:, 1].any()


# ---------------------------------------------------------------- the humanoid against MuJoCo


def test_humanoid_replay_with_frictionloss_matches_mujoco():
    """2 s multisine PD replay, frictionloss = 0.1 x effort on all 21 joints, the default solver (float32)."""
    plain = load_robot(DEFAULT_ROBOT)
    robot = load_robot(DEFAULT_ROBOT, gains={"joint": [
        {"match": name, "friction": 0.1 * float(e)} for name, e in zip(plain.joint_names, plain.effort)]})
    cmd = multisine_command(robot, 2.0, DT)
    mq, _ = mujoco_rollout(robot, cmd[0], cmd)
    mq_free, _ = mujoco_rollout(plain, cmd[0], cmd)
    q, _ = newton_rollout(robot, cmd[0], cmd)
    effect, err = np.abs(mq - mq_free), np.abs(q - mq)
    assert effect.max() > 0.2, "friction should change MuJoCo's trajectory a lot"
    # measured 0.0116 rad max, 0.0006 rad mean (float32 and float64 kernels agree); 16 sweeps 0.0027 / 0.0003,
    # 4 sweeps 0.040 / 0.0030; the older damper law (friction_kappa=FRICTION_KAPPA) 0.022 / 0.0028
    assert err.max() < 0.02 and err.mean() < 0.001
    assert err.mean() < 0.1 * effect.mean()
