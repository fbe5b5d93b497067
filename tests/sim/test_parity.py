"""Tiered parity of one robot seen by Newton, MuJoCo C and Pinocchio (nominal robots).

Tiers: model fields -> forward kinematics -> mass matrix and gravity -> one step -> a 2 s PD trajectory.
Newton computes in float32 and MuJoCo/Pinocchio in float64; each tolerance says why it has its size.
"""

import mujoco
import numpy as np
import pinocchio as pin
import pytest

from wresdyn.robot.mujoco_model import build_mujoco, mujoco_replay
from wresdyn.robot.pinocchio_model import build_pinocchio
from wresdyn.sim.parity import multisine_command
from wresdyn.sim.rollout import replay

DT = 0.002

FK_TOL = 1e-5
"""[m] Newton's float32 transforms over a ~1 m chain carry ~1e-7 m round-off; 1e-5 m leaves 100x margin
while still catching any wrong offset, axis or ordering (those give errors of cm)."""
DYN_RTOL = 1e-6
"""Relative, MuJoCo vs Pinocchio M(q) and G(q): both float64 recursive algorithms on the same numbers,
so agreement is ~1e-15; 1e-6 is the issue's bound and flags any inertia or frame error."""
STEP_TOL = 1e-5
"""One step, Newton Featherstone vs MuJoCo Euler: same semi-implicit Euler and explicit PD, differences are
float32 round-off in the accelerations (~1e-6 relative of q̇ ~ 1 rad/s); 1e-5 [rad/s] for q̇, dt x that for q."""
TRAJ_TOL_SAME_SCHEME = 1e-5
"""[rad] 2 s, 1000 steps, Newton vs MuJoCo Euler: float32 round-off accumulates (measured ~5e-7 rad)."""
TRAJ_TOL_IMPLICITFAST = 0.03
"""[rad] 2 s vs MuJoCo implicitfast (implicit actuator damping): the schemes differ by O(kd·dt/m_eff)
per step in the velocity response; measured ~0.01 rad max on the humanoid's fastest joints."""


@pytest.fixture(params=["humanoid", "quadruped"])
def robot(request):
    return request.getfixturevalue(request.param)


def _random_q(robot, rng):
    return rng.uniform(np.maximum(robot.lower, -np.pi), np.minimum(robot.upper, np.pi))


def test_tier1_model_fields(robot):
    mj = build_mujoco(robot, DT)
    assert mj.nu == mj.nv == robot.n_dof
    assert [mj.joint(i).name for i in range(mj.njnt)] == robot.joint_names
    for b, name in enumerate(robot.body_names):
        mb = mj.body(name)
        assert mb.mass[0] == pytest.approx(robot.body_mass[b], rel=1e-12)
        np.testing.assert_allclose(np.sort(mb.inertia), np.linalg.eigvalsh(robot.body_inertia[b]), rtol=1e-9, atol=1e-12)
    limited = np.isfinite(robot.lower)
    np.testing.assert_allclose(mj.jnt_range[limited], np.c_[robot.lower, robot.upper][limited])
    np.testing.assert_allclose(mj.dof_armature, robot.armature)
    np.testing.assert_allclose(mj.dof_frictionloss, robot.friction)
    np.testing.assert_allclose(mj.actuator_gainprm[:, 0], robot.kp)
    np.testing.assert_allclose(-mj.actuator_biasprm[:, 1:3], np.c_[robot.kp, robot.kd])
    finite = np.isfinite(robot.effort)
    np.testing.assert_allclose(mj.actuator_forcerange[finite, 1], robot.effort[finite])
    model = build_pinocchio(robot)
    assert model.nq == model.nv == robot.n_dof
    assert list(model.names)[1:] == robot.joint_names
    assert sum(i.mass for i in model.inertias) == pytest.approx(robot.body_mass.sum(), rel=1e-12)
    np.testing.assert_allclose(model.armature, robot.armature)
    np.testing.assert_allclose(model.lowerPositionLimit, robot.lower)


def _newton_body_positions(robot, q):
    import newton

    model = robot.build_model(1, "cpu")
    state = model.state()
    jq = state.joint_q.numpy()
    jq[robot.q_index] = q
    state.joint_q.assign(jq)
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    return state.body_q.numpy()[:, :3]


def test_tier2_forward_kinematics(robot):
    rng = np.random.default_rng(1)
    mj = build_mujoco(robot, DT)
    d = mujoco.MjData(mj)
    model = build_pinocchio(robot)
    data = model.createData()
    for _ in range(5):
        q = _random_q(robot, rng)
        p_newton = _newton_body_positions(robot, q)
        d.qpos[:] = q
        mujoco.mj_kinematics(mj, d)
        pin.framesForwardKinematics(model, data, q)
        for b, name in enumerate(robot.body_names):
            np.testing.assert_allclose(p_newton[b], d.xpos[mj.body(name).id], atol=FK_TOL)
            np.testing.assert_allclose(data.oMf[model.getFrameId(name)].translation, d.xpos[mj.body(name).id], atol=FK_TOL)
        for name in robot.frames:
            np.testing.assert_allclose(data.oMf[model.getFrameId(name)].translation, d.site(name).xpos, atol=FK_TOL)


def test_tier2_floating_base_kinematics(humanoid):
    """Free-flyer conventions: Newton/Pinocchio [x y z qx qy qz qw] vs MuJoCo [x y z qw qx qy qz]."""
    import newton

    from wresdyn.robot.description import load_robot

    r = load_robot(humanoid.source, base="floating")
    assert r.joint_type[0] == "free"
    rng = np.random.default_rng(2)
    q = _random_q(r, rng)
    quat = rng.normal(size=4)
    quat /= np.linalg.norm(quat)
    base = np.r_[0.1, -0.2, 0.9, quat]
    model = r.build_model(1, "cpu")
    state = model.state()
    jq = state.joint_q.numpy()
    jq[:7], jq[r.q_index] = base, q
    state.joint_q.assign(jq)
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    mj = build_mujoco(r, DT)
    d = mujoco.MjData(mj)
    d.qpos[:] = np.r_[base[:3], base[6], base[3:6], q]
    mujoco.mj_kinematics(mj, d)
    pm = build_pinocchio(r)
    pd = pm.createData()
    pin.framesForwardKinematics(pm, pd, np.r_[base, q])
    for b, name in enumerate(r.body_names):
        np.testing.assert_allclose(state.body_q.numpy()[b, :3], d.xpos[mj.body(name).id], atol=FK_TOL)
        np.testing.assert_allclose(pd.oMf[pm.getFrameId(name)].translation, d.xpos[mj.body(name).id], atol=FK_TOL)


def test_tier3_mass_matrix_and_gravity(robot):
    rng = np.random.default_rng(3)
    mj = build_mujoco(robot, DT)
    d = mujoco.MjData(mj)
    model = build_pinocchio(robot)
    data = model.createData()
    for _ in range(5):
        q, qd = _random_q(robot, rng), rng.normal(size=robot.n_dof)
        d.qpos[:], d.qvel[:] = q, qd
        mujoco.mj_forward(mj, d)
        m_mj = np.zeros((mj.nv, mj.nv))
        mujoco.mj_fullM(mj, d, m_mj)
        m_pin = pin.crba(model, data, q)
        m_pin = np.triu(m_pin) + np.triu(m_pin, 1).T
        np.testing.assert_allclose(m_pin, m_mj, rtol=0, atol=DYN_RTOL * np.abs(m_mj).max())
        g = pin.computeGeneralizedGravity(model, data, q)
        d.qvel[:] = 0.0
        mujoco.mj_forward(mj, d)
        np.testing.assert_allclose(g, d.qfrc_bias, rtol=0, atol=DYN_RTOL * np.abs(g).max())
        # Coriolis and centrifugal terms of eq. 1: C(q, q̇) q̇ = rnea(q, q̇, 0) - G(q)
        d.qvel[:] = qd
        mujoco.mj_forward(mj, d)
        cqd = pin.rnea(model, data, q, qd, np.zeros(robot.n_dof))
        np.testing.assert_allclose(cqd, d.qfrc_bias, rtol=0, atol=DYN_RTOL * np.abs(cqd).max())


def test_tier4_one_step(robot):
    rng = np.random.default_rng(4)
    q0, qd0 = _random_q(robot, rng), rng.normal(scale=0.5, size=robot.n_dof)
    cmd = (q0 + rng.normal(scale=0.1, size=robot.n_dof))[None]
    q_nt, qd_nt = replay(robot, cmd, q0, qd0, dt=DT, solver="featherstone")
    q_mj, qd_mj = mujoco_replay(build_mujoco(robot, DT, "Euler"), cmd, q0, qd0)
    np.testing.assert_allclose(qd_nt[1], qd_mj[1], atol=STEP_TOL)
    np.testing.assert_allclose(q_nt[1], q_mj[1], atol=STEP_TOL * DT + 1e-6)


def test_tier5_pd_trajectory_2s(robot):
    cmd = multisine_command(robot, 2.0, DT)
    q_nt, _ = replay(robot, cmd, cmd[0], dt=DT, solver="featherstone")
    q_euler, _ = mujoco_replay(build_mujoco(robot, DT, "Euler"), cmd, cmd[0])
    q_implicit, _ = mujoco_replay(build_mujoco(robot, DT, "implicitfast"), cmd, cmd[0])
    assert np.abs(q_nt - q_euler).max() < TRAJ_TOL_SAME_SCHEME
    assert np.abs(q_nt - q_implicit).max() < TRAJ_TOL_IMPLICITFAST
    # the command really moved the robot: parity is not the trivial "nothing happened"
    assert np.ptp(q_nt, axis=0).min() > 0.01
