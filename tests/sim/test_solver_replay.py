"""SolverReplay (issue 6): tiered MuJoCo parity, analytic checks, gradients against finite differences.

Tiers, each at a tolerance tied to its cause:
- tree: the structure the generated kernel bakes in, against the Robot description;
- M(q) and the bias c(q, qd) against MuJoCo C (float32 round-off on entries of size ~1);
- one step against MuJoCo ``implicitfast`` (same discretisation: semi-implicit Euler with the drive
  damping implicit), saturated drives included;
- 2 s trajectories (1000 steps) against MuJoCo ``implicitfast`` on the project humanoid and newton's
  quadruped, with no MuJoCo constraint active, so the only difference is float32 round-off;
- analytic checks for what MuJoCo models differently (penalty limits) and for implicit stability where
  explicit PD diverges (dry friction: tests/sim/test_friction.py);
- gradients through a Tape against central finite differences (float64, 3-DoF robot with a prismatic
  joint and skewed axes), and the per-step Tape against the fused rollout's (parameter gradients:
  tests/sim/test_replay_gradients.py; inertias from the model arrays: tests/sim/test_replay_params.py; the kernel
  cache: tests/sim/test_replay_cache.py).
"""

import numpy as np
import pytest
import warp as wp

from wresdyn.robot.description import load_robot
from wresdyn.sim.solver_replay import SolverReplay, TreeError

DT = 0.002

TRI_URDF = """<?xml version="1.0"?>
<robot name="tri">
  <link name="base"><inertial><mass value="2.0"/>
    <inertia ixx="0.02" iyy="0.02" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="upper"><inertial><origin xyz="0.02 0.0 -0.15" rpy="0.1 0.0 0.0"/><mass value="1.2"/>
    <inertia ixx="0.012" iyy="0.010" izz="0.003" ixy="0.001" ixz="0.0" iyz="0.0005"/></inertial></link>
  <link name="lower"><inertial><origin xyz="0.0 0.01 -0.12" rpy="0.0 0.2 0.0"/><mass value="0.8"/>
    <inertia ixx="0.006" iyy="0.005" izz="0.002" ixy="0.0" ixz="0.0004" iyz="0.0"/></inertial></link>
  <link name="slider"><inertial><origin xyz="0.0 0.0 0.03" rpy="0 0 0"/><mass value="0.5"/>
    <inertia ixx="0.001" iyy="0.0012" izz="0.0008" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <origin xyz="0 0 1.0" rpy="0 0 0.3"/><axis xyz="0 1 0"/>
    <limit lower="-2.0" upper="2.0" effort="40.0" velocity="20.0"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="lower"/>
    <origin xyz="0 0.05 -0.3" rpy="0.2 0 0"/><axis xyz="0.6 0 0.8"/>
    <limit lower="-2.0" upper="2.0" effort="30.0" velocity="20.0"/></joint>
  <joint name="slide" type="prismatic"><parent link="upper"/><child link="slider"/>
    <origin xyz="0.1 0 -0.1" rpy="0 0.3 0"/><axis xyz="0 0 1"/>
    <limit lower="-0.2" upper="0.2" effort="60.0" velocity="5.0"/></joint>
</robot>
"""
"""A 3-DoF branched robot: skewed axis, rotated joint frames, full inertia tensors, one prismatic joint."""


@pytest.fixture(scope="module")
def tri(tmp_path_factory):
    path = tmp_path_factory.mktemp("tri") / "tri.urdf"
    path.write_text(TRI_URDF)
    return load_robot(path, gains={"joint": [{"match": "*", "kp": 30.0, "kd": 1.0, "armature": 0.01}]})


def solver_for(robot, worlds=1, **kw):
    return SolverReplay(robot.build_model(worlds, "cpu", requires_grad=kw.pop("requires_grad", False)), **kw)


def inside_limits(robot):
    """A centre pose and sinusoid amplitude that keep every joint clear of its limits."""
    span = np.where(np.isfinite(robot.upper - robot.lower), robot.upper - robot.lower, 2.0)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -1.0)
    hi = np.where(np.isfinite(robot.upper), robot.upper, 1.0)
    return np.clip(np.zeros(robot.n_dof), lo + 0.3 * span, hi - 0.3 * span), np.minimum(0.2, 0.12 * span)


def commands(robot, steps, seed=0):
    center, amp = inside_limits(robot)
    freq = np.random.default_rng(seed).uniform(0.3, 1.0, robot.n_dof)
    t = np.arange(steps)[:, None] * DT
    return center, center + amp * np.sin(2 * np.pi * freq * t)


def rollout(solver, q0, qd0, cmd, joint_f=None, dtype=np.float32):
    """Fused rollout of one world (robot DoF order = Newton order for these robots)."""
    t_len, n = cmd.shape
    assert (solver.tree.q_offset == np.arange(n)).all() and (solver.tree.qd_offset == np.arange(n)).all()
    q = np.zeros((t_len + 1, 1, n), dtype)
    qd = np.zeros((t_len + 1, 1, n), dtype)
    q[0, 0], qd[0, 0] = q0, qd0
    wdt = wp.float64 if dtype == np.float64 else wp.float32
    qa, qda = wp.array(q, dtype=wdt), wp.array(qd, dtype=wdt)
    f = None if joint_f is None else wp.array(joint_f[:, None].astype(dtype), dtype=wdt)
    solver.rollout(qa, qda, wp.array(cmd[:, None].astype(dtype), dtype=wdt), DT, joint_f=f)
    return qa.numpy()[:, 0], qda.numpy()[:, 0]


def step_tape(solver, q0, tq, jf, qd0=None):
    """A Tape over ``solver.step`` for each row of targets ``tq`` and residual torques ``jf`` (T, W, n) from
    ``q0`` (and ``qd0``) (W, n), on per-step states and controls of the solver's model: (states, controls, tape)."""
    model, t_len = solver.model, tq.shape[0]
    states = [model.state(requires_grad=True) for _ in range(t_len + 1)]
    controls = [model.control(requires_grad=True) for _ in range(t_len)]
    states[0].joint_q.assign(q0.ravel().astype(np.float32))
    if qd0 is not None:
        states[0].joint_qd.assign(qd0.ravel().astype(np.float32))
    tape = wp.Tape()
    with tape:
        for k in range(t_len):
            controls[k].joint_target_q.assign(tq[k].ravel().astype(np.float32))
            controls[k].joint_f.assign(jf[k].ravel().astype(np.float32))
            solver.step(states[k], states[k + 1], controls[k], None, DT)
    return states, controls, tape


def rollout_tape(solver, q0, tq, jf):
    """A Tape over the fused ``solver.rollout`` of targets ``tq`` and residual torques ``jf`` (T, W, n) from ``q0``
    (W, n) at rest, float32: (q, qd, target_q, joint_f arrays, tape)."""
    t_len, w, n = tq.shape
    q = wp.array(np.concatenate([q0[None], np.zeros((t_len, w, n))]).astype(np.float32), requires_grad=True)
    qd = wp.zeros((t_len + 1, w, n), requires_grad=True)
    tqa = wp.array(tq.astype(np.float32), requires_grad=True)
    jfa = wp.array(jf.astype(np.float32), requires_grad=True)
    tape = wp.Tape()
    with tape:
        solver.rollout(q, qd, tqa, DT, joint_f=jfa)
    return q, qd, tqa, jfa, tape


def mujoco_run(robot, q0, qd0, cmd):
    import mujoco

    from wresdyn.robot.mujoco_model import build_mujoco

    m = build_mujoco(robot, DT, "implicitfast")
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = q0, qd0
    q, qd, constrained = [d.qpos.copy()], [d.qvel.copy()], 0
    for c in cmd:
        d.ctrl[:] = c
        mujoco.mj_step(m, d)
        q.append(d.qpos.copy())
        qd.append(d.qvel.copy())
        constrained = max(constrained, d.nefc)
    return np.array(q), np.array(qd), constrained


# ---------------------------------------------------------------- tree


def test_tree_holds_the_robot(humanoid, tri):
    for robot in (humanoid, tri):
        tree = solver_for(robot, 3).tree
        assert tree.n_dof == robot.n_dof and tree.world_count == 3
        assert (tree.q_offset == robot.q_index).all() and (tree.qd_offset == robot.qd_index).all()
        dof_of_body = {int(b): k for k, b in enumerate(robot.dof_body)}
        expected_parent = [dof_of_body.get(int(robot.body_parent[b]), -1) for b in robot.dof_body]
        assert list(tree.parent) == expected_parent
        # every body but the fixed base belongs to the group of the DoF that moves it (no welded bodies here)
        assert tree.body_dof[0] == -1 and list(tree.body_dof[robot.dof_body]) == list(range(robot.n_dof))
    assert list(solver_for(tri).tree.prismatic) == [False, False, True]


def test_floating_base_is_refused(humanoid):
    floating = load_robot(humanoid.source, base="floating")
    with pytest.raises(TreeError, match="fixed-base"):
        solver_for(floating)


# ---------------------------------------------------------------- M(q), c(q, qd) and one step vs MuJoCo


@pytest.mark.parametrize("name", ["humanoid", "quadruped", "tri"])
def test_mass_matrix_and_bias_match_mujoco(name, request):
    import mujoco

    from wresdyn.robot.mujoco_model import build_mujoco

    robot = request.getfixturevalue(name)
    # float32 kernels: entries of size ~1 carry ~1e-7 round-off through ~100 operations; float64 kernels
    # are limited by the model's parameters, which Newton stores in float32 (relative 6e-8)
    dtype, tol = (wp.float64, 2e-7) if name == "tri" else (wp.float32, 2e-5)
    solver = solver_for(robot, dtype=dtype)
    rng = np.random.default_rng(1)
    center, _ = inside_limits(robot)
    q = center + rng.uniform(-0.3, 0.3, (4, robot.n_dof))
    qd = rng.uniform(-2.0, 2.0, (4, robot.n_dof))
    M, c = solver.dynamics_terms(q, qd)
    m = build_mujoco(robot, DT)
    d = mujoco.MjData(m)
    for i in range(len(q)):
        d.qpos[:], d.qvel[:] = q[i], qd[i]
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        full -= np.diag(robot.armature)
        assert np.abs(M[i] - full).max() <= tol * max(1.0, np.abs(full).max())
        assert np.abs(c[i] - d.qfrc_bias).max() <= tol * max(1.0, np.abs(d.qfrc_bias).max())


@pytest.mark.parametrize("name", ["humanoid", "quadruped"])
def test_one_step_matches_mujoco_implicitfast(name, request):
    robot = request.getfixturevalue(name)
    solver = solver_for(robot)
    rng = np.random.default_rng(2)
    center, _ = inside_limits(robot)
    qd0 = rng.normal(scale=2.0, size=robot.n_dof)
    target = center + rng.uniform(-0.2, 0.2, robot.n_dof)
    target[:2] += np.array([1.0, -1.0]) * 2.0 * robot.effort[:2] / robot.kp[:2]  # two drives saturate
    q, qd = rollout(solver, center, qd0, target[None])
    mq, mqd, _ = mujoco_run(robot, center, qd0, target[None])
    # |qdd| ~ 1e3 rad/s^2 in float32: dt * qdd carries ~1e-6 rad/s; a drive damping applied while
    # saturated (as explicit PD codes often do) would be off by ~1e-1
    assert np.abs(qd[1] - mqd[1]).max() < 5e-5
    assert np.abs(q[1] - mq[1]).max() < 3e-7 + DT * 5e-5  # plus float32 rounding of |q| <~ 2 rad


# ---------------------------------------------------------------- 2 s trajectories


@pytest.mark.parametrize("name", ["humanoid", "quadruped"])
def test_two_second_trajectory_matches_mujoco_implicitfast(name, request):
    robot = request.getfixturevalue(name)
    center, cmd = commands(robot, 1000)
    mq, mqd, constrained = mujoco_run(robot, center, np.zeros(robot.n_dof), cmd)
    assert constrained == 0, "the reference trajectory must stay clear of MuJoCo's limit constraints"
    solver = solver_for(robot)
    q, qd = rollout(solver, center, np.zeros(robot.n_dof), cmd)
    assert np.ptp(q, axis=0).max() > 0.2, "the trajectory should move"
    # same integrator, so only float32 round-off separates them (measured ~2e-7 rad on the humanoid);
    # treating the drive damping explicitly instead would differ by ~1e-3 rad within 100 steps
    assert np.abs(q - mq).max() < 1e-5
    assert np.abs(qd - mqd).max() < 1e-3

    # Newton's step() API on flat state arrays gives the same trajectory as the fused rollout
    model = solver.model
    s0, s1, ctrl = model.state(), model.state(), model.control()
    s0.joint_q.assign(center.astype(np.float32))
    for k in range(200):
        ctrl.joint_target_q.assign(cmd[k].astype(np.float32))
        solver.step(s0, s1, ctrl, None, DT)
        s0, s1 = s1, s0
    assert np.abs(s0.joint_q.numpy() - q[200]).max() < 1e-6


def test_implicit_damping_is_stable_where_explicit_pd_is_not():
    from wresdyn.sim.solvers import explicit_pd_margin

    # no armature, high damping: kd dt / m_eff >> 2 on the knees, so explicit PD (SolverFeatherstone) diverges
    robot = load_robot("newton:quadruped.urdf", gains={"joint": [{"match": "*", "kp": 50.0, "kd": 10.0}]})
    assert explicit_pd_margin(robot, DT).max() > 2.0
    center, cmd = commands(robot, 500)
    q, qd = rollout(solver_for(robot), center, np.zeros(robot.n_dof), cmd)
    mq, _, constrained = mujoco_run(robot, center, np.zeros(robot.n_dof), cmd)
    assert constrained == 0 and np.isfinite(q).all()
    assert np.abs(q - mq).max() < 1e-5


def test_implicit_stiffness_option_keeps_very_stiff_drives_stable():
    """kp dt^2 / m_eff >> 4 (no armature, kp = 2e4): explicit stiffness diverges, implicit settles on the target."""
    robot = load_robot("newton:quadruped.urdf", gains={"joint": [{"match": "*", "kp": 2e4, "kd": 2.0, "effort": 1e9}]})
    target = np.full((300, robot.n_dof), 0.2)
    q, _ = rollout(solver_for(robot), np.zeros(robot.n_dof), np.zeros(robot.n_dof), target)
    assert not np.isfinite(q).all() or np.abs(q).max() > 10.0
    q, _ = rollout(solver_for(robot, implicit_stiffness=True), np.zeros(robot.n_dof), np.zeros(robot.n_dof), target)
    # gravity / kp leaves a ~1e-3 rad offset
    assert np.isfinite(q).all() and np.abs(q[-1] - 0.2).max() < 5e-3


# ---------------------------------------------------------------- analytic checks


def zero_gravity(solver):
    solver.model.gravity.zero_()
    solver.notify_model_changed(0)  # float64 solvers hold a copy


def test_joint_limit_penalty_balances_the_drive(tri):
    """Driven past the upper limit, the joint settles where kp (q* - q) = limit_ke (q - upper)."""
    solver = solver_for(tri, dtype=wp.float64)
    zero_gravity(solver)
    kp, lke, upper = 30.0, float(solver.model.joint_limit_ke.numpy()[0]), tri.upper[0]
    target = np.array([upper + 0.5, 0.0, 0.0])
    q, qd = rollout(solver, np.zeros(3), np.zeros(3), np.tile(target, (1500, 1)), dtype=np.float64)
    expected = (kp * target[0] + lke * upper) / (kp + lke)
    assert np.isfinite(q).all() and abs(qd[-1, 0]) < 1e-3
    assert q[-1, 0] == pytest.approx(expected, abs=1e-5) and q[-1, 0] > upper


# ---------------------------------------------------------------- gradients


def test_gradients_match_central_differences(tri):
    """d loss / d (q0, qd0, target_q, joint_f) through a 10-step Tape, float64, friction on."""
    gains = {"joint": [{"match": "*", "kp": 30.0, "kd": 1.0, "armature": 0.01, "friction": 0.3}]}
    robot = load_robot(tri.source, gains=gains)
    solver = solver_for(robot, 2, requires_grad=True, dtype=wp.float64)
    T, W, n = 10, 2, 3
    rng = np.random.default_rng(0)
    q0 = np.array([[0.3, -0.2, 0.05], [0.1, 0.4, -0.1]])
    qd0, tq, jf = rng.normal(size=(W, n)), rng.normal(scale=0.3, size=(T, W, n)), rng.normal(scale=0.5, size=(T, W, n))
    weights = rng.normal(size=(W, n))

    def arrays(q0, qd0, tq, jf, grad):
        q, qd = np.zeros((T + 1, W, n)), np.zeros((T + 1, W, n))
        q[0], qd[0] = q0, qd0
        return [wp.array(a, dtype=wp.float64, requires_grad=grad) for a in (q, qd, tq, jf)]

    def loss_of(q, qd):
        return float((q[T] * weights).sum() + 0.1 * (qd[T] * weights).sum())

    def value(q0, qd0, tq, jf):
        q, qd, tqa, jfa = arrays(q0, qd0, tq, jf, False)
        solver.rollout(q, qd, tqa, DT, joint_f=jfa)
        return loss_of(q.numpy(), qd.numpy())

    q, qd, tqa, jfa = arrays(q0, qd0, tq, jf, True)
    tape = wp.Tape()
    with tape:
        solver.rollout(q, qd, tqa, DT, joint_f=jfa)
    seed_q, seed_qd = np.zeros((T + 1, W, n)), np.zeros((T + 1, W, n))
    seed_q[T], seed_qd[T] = weights, 0.1 * weights
    tape.backward(grads={q: wp.array(seed_q, dtype=wp.float64), qd: wp.array(seed_qd, dtype=wp.float64)})
    grads = {"q0": q.grad.numpy()[0], "qd0": qd.grad.numpy()[0], "tq": tqa.grad.numpy(), "jf": jfa.grad.numpy()}
    inputs = {"q0": q0, "qd0": qd0, "tq": tq, "jf": jf}
    eps = 1e-6
    for key, idx in [("q0", (0, 0)), ("q0", (1, 2)), ("qd0", (0, 1)), ("qd0", (1, 0)),
                     ("tq", (0, 0, 0)), ("tq", (5, 1, 2)), ("jf", (0, 0, 1)), ("jf", (9, 1, 0))]:
        plus, minus = {k: v.copy() for k, v in inputs.items()}, {k: v.copy() for k, v in inputs.items()}
        plus[key][idx] += eps
        minus[key][idx] -= eps
        fd = (value(**plus) - value(**minus)) / (2 * eps)
        # float64 central differences: truncation ~eps^2, round-off ~1e-16 / eps
        assert grads[key][idx] == pytest.approx(fd, rel=1e-6, abs=1e-9), (key, idx)


def test_step_tape_matches_rollout_tape_and_threads_agree(tri):
    """float32: a Tape over step() on per-step states gives the rollout's gradients; 2 CPU threads change nothing."""
    T, W, n = 8, 3, 3
    solver = solver_for(tri, W, requires_grad=True)
    threaded = SolverReplay(solver.model, threads=2)
    rng = np.random.default_rng(4)
    q0, tq, jf = rng.uniform(-0.3, 0.3, (W, n)), rng.uniform(-0.3, 0.3, (T, W, n)), rng.normal(size=(T, W, n))

    def via_rollout(s):
        q, _, _, jfa, tape = rollout_tape(s, q0, tq, jf)
        seed = np.zeros((T + 1, W, n), np.float32)
        seed[T] = 1.0
        tape.backward(grads={q: wp.array(seed)})
        return q.numpy()[T], q.grad.numpy()[0], jfa.grad.numpy()

    states, controls, tape = step_tape(solver, q0, tq, jf)
    tape.backward(grads={states[T].joint_q: wp.array(np.ones(W * n, np.float32))})
    q_end, g_q0, g_jf = via_rollout(solver)
    assert np.abs(states[T].joint_q.numpy() - q_end.ravel()).max() < 1e-6
    assert np.allclose(states[0].joint_q.grad.numpy(), g_q0.ravel(), rtol=1e-4, atol=1e-6)
    assert np.allclose(np.stack([c.joint_f.grad.numpy() for c in controls]), g_jf.reshape(T, -1), rtol=1e-4, atol=1e-8)
    assert np.abs(g_jf).max() > 1e-4
    t_end, t_q0, t_jf = via_rollout(threaded)
    assert np.array_equal(t_end, q_end) and np.array_equal(t_q0, g_q0) and np.array_equal(t_jf, g_jf)


def test_selectable_in_sim(humanoid):
    """``solver="replay"`` in :mod:`wresdyn.sim.solvers` gives the same replay as the fused rollout."""
    from wresdyn.sim import SOLVERS, make_solver
    from wresdyn.sim.rollout import replay

    assert "replay" in SOLVERS
    assert isinstance(make_solver(humanoid.build_model(1, "cpu"), humanoid, DT, "replay"), SolverReplay)
    center, cmd = commands(humanoid, 50)
    q, _ = replay(humanoid, cmd, center, dt=DT, solver="replay")
    q_ref, _ = rollout(solver_for(humanoid), center, np.zeros(humanoid.n_dof), cmd)
    assert np.abs(q - q_ref).max() < 1e-6
