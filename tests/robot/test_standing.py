"""The floating-base robot on the ground: Newton (SolverMuJoCo) and the MuJoCo C real robot, nominal.

Tiers: the two compiled MuJoCo models' contact fields (geoms, materials, solver options) -> the free joint's
conventions and the standing start against MuJoCo's own kinematics and collision distances -> a 1 s PD stance in
both simulators. Then the real robot's mismatch on a floating base, and the requests that must fail.
"""

import mujoco
import numpy as np
import pytest
import torch

from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.robot.description import RobotError, load_robot
from wresdyn.robot.ground import ContactSettings, FloatingState, standing_state
from wresdyn.robot.mujoco_model import build_mujoco, free_from_mujoco, free_to_mujoco
from wresdyn.sim import Simulator

RATE = 500.0
DT = 1.0 / RATE
STANCE_S = 1.0
"""Length of the PD stance [s]. The humanoid holding its neutral pose under its own PD gains is statically unstable
(ankle stiffness 2 x 40 N*m/rad against m g h ~ 170 N*m/rad): it tips backwards, its pitch growing ~4-8x every
0.5 s from the 1e-5 rad the landing leaves, and falls after ~3 s. Over 1 s it tilts < 2e-3 rad."""

POS_TOL = 1e-4
"""[m] base position, Newton vs MuJoCo C over the stance (measured 7e-6 m). Both run MuJoCo's contact solver on the
same geoms, but Newton's model and state are float32 and its MuJoCo model is converted with its own conventions
(joint limits' solref from Newton's limit stiffness, effort limits as joint actuator force ranges; both inactive in
a stance): differences of ~1e-7 enter while the feet settle 0.5 mm into the soft contact in the first 20 ms, and
the stance's instability then grows them (see STANCE_S). 10x margin over the measurement."""
ANGLE_TOL = 1e-4
"""[rad] base orientation, angle between the two quaternions (measured 1.1e-5 rad); same reasons as POS_TOL."""
JOINT_TOL = 2e-4
"""[rad] joint angles (measured 1.4e-5 rad); same reasons as POS_TOL."""
TWIST_TOL = 1e-3
"""[m/s, rad/s] base twist (measured 1.1e-4); same reasons as POS_TOL, 9x margin."""
MIN_HEIGHT = 0.79
"""[m] a standing humanoid's base stays above this: it starts at 0.80 m and sinks 0.55 mm into the soft contact
(solref 0.02 s: a deflection of m g / k); free fall would take it below 0 in 1 s."""
FK_TOL = 1e-6
"""[m] Newton's float32 forward kinematics against MuJoCo's float64 over a ~1 m chain (round-off ~1e-7 m)."""


@pytest.fixture(scope="module")
def floating():
    return load_robot("scenes/humanoid.usda", base="floating")


@pytest.fixture(scope="module")
def quadruped_floating():
    from conftest import QUADRUPED_GAINS

    return load_robot("newton:quadruped.urdf", gains=QUADRUPED_GAINS, base="floating")


def _angle(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    """Rotation angle [rad] between quaternions [x y z w], shape (..., 4) (arccos of their dot product would lose
    the small angles to round-off)."""
    from scipy.spatial.transform import Rotation as R

    return (R.from_quat(np.asarray(qa, dtype=np.float64)).inv() * R.from_quat(np.asarray(qb, np.float64))).magnitude()


def test_contact_fields_match_solver_mujoco(floating):
    """build_mujoco's floor and collision geoms are, field by field, the MuJoCo model Newton's SolverMuJoCo compiles
    from the Newton model with a ground (same ContactSettings), and so are the solver options."""
    from wresdyn.sim.solvers import make_solver

    contact = ContactSettings(friction=0.8, timeconst=0.01, dampratio=0.9, gap=0.01, cone="elliptic", iterations=50)
    for c in (ContactSettings(), contact):
        model = floating.build_model(1, "cpu", ground=True, contact=c)
        newton_mj = make_solver(model, floating, DT, "mujoco", ground=True, contact=c).mj_model
        ours = build_mujoco(floating, DT, ground=True, contact=c)
        assert ours.ngeom == newton_mj.ngeom == 23  # the floor and 22 boxes (the sole spheres are sites)
        names = lambda m: [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, g) for g in range(m.ngeom)]  # noqa: E731
        assert names(ours) == names(newton_mj)
        for f in ("type", "bodyid", "condim", "contype", "conaffinity", "priority"):
            np.testing.assert_array_equal(getattr(ours, f"geom_{f}"), getattr(newton_mj, f"geom_{f}"), err_msg=f)
        # Newton's numbers are float32
        for f in ("size", "pos", "quat", "friction", "solref", "solimp", "margin", "gap", "solmix"):
            np.testing.assert_allclose(getattr(ours, f"geom_{f}"), getattr(newton_mj, f"geom_{f}"), rtol=1e-6,
                                       atol=1e-7, err_msg=f)
        np.testing.assert_allclose(ours.geom_friction[0], [c.friction, c.torsional_friction, c.rolling_friction],
                                   rtol=1e-6)
        np.testing.assert_allclose(ours.geom_solref[0], c.solref, rtol=1e-6)
        for f in ("timestep", "integrator", "cone", "solver", "iterations", "ls_iterations", "impratio", "tolerance",
                  "ls_tolerance", "jacobian", "disableflags", "enableflags", "noslip_iterations"):
            assert getattr(ours.opt, f) == pytest.approx(getattr(newton_mj.opt, f)), f


def test_free_joint_conventions(quadruped_floating):
    """Newton's free joint (pose [p, q_xyzw], twist [centre-of-mass velocity, angular velocity] in world axes) and
    MuJoCo's (qpos [p, q_wxyz], qvel [origin velocity in world axes, angular velocity in body axes]) give the same
    body pose and velocity, on a base whose centre of mass is off its origin; the conversion round-trips."""
    import newton

    robot = quadruped_floating
    assert np.linalg.norm(robot.body_com[0]) > 0.01
    rng = np.random.default_rng(0)
    quat = rng.standard_normal(4)
    pose = np.concatenate([[0.1, -0.2, 0.5], quat / np.linalg.norm(quat)])
    twist = rng.uniform(-1.0, 1.0, 6)
    q = np.clip(rng.uniform(-0.5, 0.5, robot.n_dof), robot.lower, robot.upper)
    qd = rng.uniform(-1.0, 1.0, robot.n_dof)

    model = robot.build_model(1, "cpu")
    state = model.state()
    joint_q, joint_qd = model.joint_q.numpy(), np.zeros(model.joint_dof_count, dtype=np.float32)
    joint_q[:7], joint_qd[:6] = pose, twist
    joint_q[robot.q_index], joint_qd[robot.qd_index] = q, qd
    state.joint_q.assign(joint_q)
    state.joint_qd.assign(joint_qd)
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    body_q, body_qd = state.body_q.numpy()[0], state.body_qd.numpy()[0]

    m = build_mujoco(robot, DT)
    d = mujoco.MjData(m)
    d.qpos[:7], d.qvel[:6] = free_to_mujoco(robot, pose, twist)
    d.qpos[7:], d.qvel[6:] = q, qd
    mujoco.mj_forward(m, d)
    np.testing.assert_allclose(d.xpos[1], body_q[:3], atol=FK_TOL)
    assert _angle(d.xquat[1][[1, 2, 3, 0]], body_q[3:]) < FK_TOL
    vel = np.zeros(6)
    mujoco.mj_objectVelocity(m, d, mujoco.mjtObj.mjOBJ_BODY, 1, vel, 0)  # [w, v] at the centre of mass, world axes
    np.testing.assert_allclose(vel[3:], body_qd[:3], atol=1e-5)
    np.testing.assert_allclose(vel[:3], body_qd[3:], atol=1e-5)
    back = free_from_mujoco(robot, d.qpos[:7], d.qvel[:6])
    np.testing.assert_allclose(back[0], pose, atol=1e-12)
    np.testing.assert_allclose(back[1], twist, atol=1e-12)


@pytest.mark.parametrize("pose", ["neutral", "random"])
def test_standing_start_touches_the_floor(floating, pose):
    """The lowest collision geometry of the standing start is on the floor, by MuJoCo's own collision distance."""
    rng = np.random.default_rng(1)
    q = floating.q0 if pose == "neutral" else rng.uniform(np.maximum(floating.lower, -1.0),
                                                        np.minimum(floating.upper, 1.0))
    st = standing_state(floating, q)
    np.testing.assert_array_equal(st.base_pose[[0, 1, 3, 4, 5]], 0.0)
    if pose == "neutral":
        assert st.base_pose[2] == pytest.approx(0.8, abs=FK_TOL)  # the USD scene stands its soles on z = 0
    m = build_mujoco(floating, DT, ground=True)
    d = mujoco.MjData(m)
    d.qpos[:7], _ = free_to_mujoco(floating, st.base_pose, st.base_twist)
    d.qpos[7:] = st.q
    mujoco.mj_forward(m, d)
    floor = 0
    dist = [mujoco.mj_geomDistance(m, d, floor, g, 1.0, None) for g in range(1, m.ngeom)]
    assert min(dist) == pytest.approx(0.0, abs=FK_TOL)


def _stance(floating, seconds):
    """Hold the neutral pose from the standing start in Newton and in the nominal MuJoCo C robot; per step the base
    pose (7), base twist (6) and joints (n) of each, shapes (T, 13 + n)."""
    st = standing_state(floating)
    sim = Simulator(floating, 1, DT, solver="mujoco", ground=True)
    t = lambda a: torch.as_tensor(a, dtype=torch.float32)[None]  # noqa: E731
    sim.set_full_state(None, t(st.base_pose), t(st.base_twist), t(st.q), t(st.qd))
    real = RealRobot(floating, Mismatch(), RATE)
    real.reset(st)
    newton_out, mujoco_out = [], []
    for _ in range(round(seconds * RATE)):
        q, _ = sim.step(t(floating.q0))
        obs = real.step(floating.q0)
        newton_out.append(np.concatenate([sim.base_pose[0].numpy(), sim.base_twist[0].numpy(), q[0].numpy()]))
        mujoco_out.append(np.concatenate([obs.base_pose, obs.base_twist, obs.q]))
    return np.array(newton_out, dtype=np.float64), np.array(mujoco_out)


def test_stance_parity_newton_vs_mujoco_c(floating):
    """1 s of PD stance: Newton's SolverMuJoCo and the MuJoCo C robot agree on the base and the joints, and stand."""
    torch.set_num_threads(1)
    a, b = _stance(floating, STANCE_S)
    for x in (a, b):
        assert x[:, 2].min() > MIN_HEIGHT
        assert _angle(x[:, 3:7], np.array([0.0, 0.0, 0.0, 1.0])).max() < 0.01  # upright
    assert np.abs(a[:, :3] - b[:, :3]).max() < POS_TOL
    assert _angle(a[:, 3:7], b[:, 3:7]).max() < ANGLE_TOL
    assert np.abs(a[:, 7:13] - b[:, 7:13]).max() < TWIST_TOL
    assert np.abs(a[:, 13:] - b[:, 13:]).max() < JOINT_TOL


@pytest.mark.slow
def test_worlds_stand_independently_on_mujoco_warp(floating):
    """Several worlds on the CPU run on mujoco_warp (Newton's MuJoCo C backend holds one world): world 0 agrees with
    the MuJoCo C robot as Newton's MuJoCo C path does (same tolerances, measured the same 7e-6 m / 1.4e-5 rad), and
    world 1, dropped from 5 cm at x = 1 m, lands and stands in its own world. Slow: mujoco_warp's kernels compile
    for Warp's CPU device on first use (~30 s without a kernel cache)."""
    torch.set_num_threads(1)
    st = standing_state(floating)
    sim = Simulator(floating, 2, DT, solver="mujoco", ground=True)
    assert not sim.solver.use_mujoco_cpu
    t = lambda a: torch.as_tensor(a, dtype=torch.float32)[None].repeat(2, 1)  # noqa: E731
    pose = t(st.base_pose)
    pose[1, 0], pose[1, 2] = 1.0, pose[1, 2] + 0.05
    sim.set_full_state(None, pose, t(st.base_twist), t(st.q), t(st.qd))
    real = RealRobot(floating, Mismatch(), RATE)
    real.reset(st)
    for _ in range(round(STANCE_S * RATE)):
        q, _ = sim.step(t(floating.q0))
        obs = real.step(floating.q0)
        base = sim.base_pose.numpy().astype(np.float64)
        assert np.abs(base[0, :3] - obs.base_pose[:3]).max() < POS_TOL
        assert _angle(base[0, 3:], obs.base_pose[3:]) < ANGLE_TOL
        assert np.abs(q[0].numpy() - obs.q).max() < JOINT_TOL
    assert base[1, 0] == pytest.approx(1.0, abs=0.01) and base[1, 2] == pytest.approx(obs.base_pose[2], abs=1e-3)


def test_the_robot_stands_on_the_floor(floating):
    """The MuJoCo C robot holds its pose on the floor: feet on it (not through it), base at its start height."""
    real = RealRobot(floating, Mismatch(), RATE)
    st = standing_state(floating)
    real.reset(st)
    for _ in range(int(STANCE_S * RATE)):
        obs = real.step(floating.q0)
    d = real._data
    assert d.ncon >= 8  # both soles flat: 4 corners each
    assert d.contact.dist[: d.ncon].min() > -1e-3  # a soft contact's deflection, not sinking through
    assert obs.base_pose[2] == pytest.approx(st.base_pose[2], abs=1e-3)
    assert np.abs(obs.q - floating.q0).max() < 0.01


def test_floating_real_robot_mismatch(floating):
    """The mismatch reaches the joints of a floating base (MuJoCo dof 6 + i is joint i) and its delay shifts the
    commands of step exactly, as record's; sensor noise lands on the joints only."""
    mm = Mismatch(friction=0.1, damping=0.5, armature_scale=2.0)
    real = RealRobot(floating, mm, RATE)
    np.testing.assert_array_equal(real.model.dof_frictionloss[:6], 0.0)
    np.testing.assert_allclose(real.model.dof_frictionloss[6:], 0.1 * floating.effort)
    np.testing.assert_allclose(real.model.dof_damping[6:], 0.5 * floating.kd)
    physics = real.physics()
    np.testing.assert_allclose(physics.friction, 0.1 * floating.effort)
    np.testing.assert_allclose(physics.armature, 2.0 * floating.armature)

    st = standing_state(floating)
    rng = np.random.default_rng(0)
    cmds = floating.q0 + 0.02 * rng.standard_normal((40, floating.n_dof))
    m = 3
    delayed = RealRobot(floating, Mismatch(delay=m / RATE, substep=0.001), RATE)
    nominal = RealRobot(floating, Mismatch(substep=0.001), RATE)
    delayed.reset(st)
    nominal.reset(st)
    padded = np.concatenate([np.repeat(st.q[None], m, axis=0), cmds])
    for k in range(len(cmds)):
        a, b = delayed.step(cmds[k]), nominal.step(padded[k])
        np.testing.assert_array_equal(a.q, b.q)
        np.testing.assert_array_equal(a.base_pose, b.base_pose)

    noisy = RealRobot(floating, Mismatch(position_noise=1e-3), RATE)
    with pytest.raises(ValueError, match="Generator"):
        noisy.reset(st)
    noisy.reset(st, np.random.default_rng(1))
    obs = noisy.step(floating.q0)
    true = noisy.state
    assert 1e-4 < np.abs(obs.q - true.q).max() < 1e-2
    np.testing.assert_array_equal(obs.base_pose, true.base_pose)


def test_bad_requests_fail_clearly(floating, humanoid):
    """One-line errors: a ground with a solver without contacts or with gradients; the stand's and the floor's
    methods on the wrong base."""
    for solver in ("replay", "featherstone"):
        with pytest.raises(ValueError, match="ground needs solver 'mujoco'") as e:
            Simulator(floating, 1, DT, solver=solver, ground=True)
        assert "\n" not in str(e.value)
    with pytest.raises(ValueError, match="not differentiable"):
        Simulator(floating, 1, DT, ground=True, requires_grad=True)
    with pytest.raises(ValueError, match="contact settings without a ground"):
        floating.build_model(1, "cpu", contact=ContactSettings())
    with pytest.raises(ValueError, match="base is fixed"):
        _ = Simulator(humanoid, 1, DT).base_pose
    with pytest.raises(RobotError, match="floating base"):
        standing_state(humanoid)
    with pytest.raises(ValueError, match="record runs on a stand"):
        RealRobot(floating).record(np.zeros((2, floating.n_dof)))
    st = FloatingState(np.array([0, 0, 1, 0, 0, 0, 1.0]), np.zeros(6), humanoid.q0, np.zeros(humanoid.n_dof))
    with pytest.raises(ValueError, match="fixed base records with record"):
        RealRobot(humanoid).reset(st)
    with pytest.raises(Exception, match="contact friction"):
        ContactSettings(friction=-1.0)
    with pytest.raises(RobotError, match="cone"):
        ContactSettings(cone="round")
