"""Servo drives in SolverReplay: selection per joint, the law against its numpy form, gradients of the
new fields against central finite differences (float64, the set-up of ``test_replay_gradients.py``), the goal
profile in torch against numpy, and the parameter file round trip.
"""

import json

import numpy as np
import pytest
import torch
import warp as wp
from test_replay_gradients import ATOL, DT, RTOL, N, Problem, T, W, check, random_inputs
from test_solver_replay import TRI_URDF

from conftest import check_directional_gradients
from wresdyn.robot.description import load_robot
from wresdyn.robot.physical import PhysicalParams
from wresdyn.robot.servo import GoalProfile, read_servo, servo_torque
from wresdyn.sim.bank import profile_goals
from wresdyn.sim.solver_replay import SolverReplay
from wresdyn.sim.solver_replay.codegen import generate_source
from wresdyn.errors import RobotError

SERVO = {"drive": "servo", "deadband": 0.05, "noload_speed": 10.0, "goal_accel": 40.0}
"""Servo settings of the test robot's revolute joints: a dead band the 0.2 rad targets leave, a torque-speed line
(U / w0 = 2 N m s/rad) that matters against kp = 30."""


def make_robot(tmp_path, effort=20.0, joints="*", **servo):
    path = tmp_path / "tri.urdf"
    path.write_text(TRI_URDF)
    gains = {"joint": [{"match": "*", "kp": 30.0, "kd": 1.0, "armature": 0.01, "damping": 0.2, "friction": 0.3,
                        "effort": effort},
                       {"match": joints, **SERVO, **servo}]}
    return load_robot(path, gains=gains)


def test_selection_per_joint(tmp_path):
    robot = make_robot(tmp_path, joints="elbow")
    assert robot.servo.mask.tolist() == [False, True, False]
    assert robot.servo.deadband.tolist() == [0.0, 0.05, 0.0]
    model = robot.build_model(2, "cpu")
    assert model.joint_servo.numpy().tolist() == [0, 1, 0, 0, 1, 0]
    assert make_robot(tmp_path, joints="*").servo.mask.all()
    p = PhysicalParams.nominal(robot)
    assert p.noload_speed.tolist() == [0.0, 10.0, 0.0]
    with pytest.raises(RobotError, match="drive"):
        read_servo({"joint": [{"match": "*", "drive": "bam"}]}, ["a"], [1.0])
    with pytest.raises(RobotError, match="effort"):
        read_servo({"joint": [{"match": "*", "drive": "servo"}]}, ["a"], [np.inf])
    assert read_servo({"joint": [{"match": "*", "kp": 1.0}]}, ["a"], [1.0]) is None


def test_pd_robot_source_unchanged(tmp_path):
    """A model without servo joints generates the source it did before servos existed: no new arguments or
    statements (the bit-for-bit guarantee for PD robots)."""
    from wresdyn.sim.solver_replay.tree import tree_from_model

    path = tmp_path / "tri.urdf"
    path.write_text(TRI_URDF)
    tree = tree_from_model(load_robot(path, gains={"joint": [{"match": "*", "kp": 30.0}]}).build_model(1, "cpu"))
    pd = generate_source(tree)
    assert pd == generate_source(tree, servo=np.zeros(N, bool))
    assert "sdb" not in pd and "sdb" in generate_source(tree, servo=np.array([False, True, False]))


def test_one_step_matches_the_law(tmp_path):
    """One float64 step without dry friction against the law written in numpy (:func:`servo_torque`) and the step of
    the solver's docstring: ``H (v - qd) = dt (tau - c - d qd)``, ``H = M + A + dt D``, ``D`` the servo's
    ``kd + U / w0`` plus the passive damping, once with the errors outside the dead band and once inside."""
    robot = make_robot(tmp_path, joints="*")
    solver = SolverReplay(robot.build_model(1, "cpu"), dtype=wp.float64, friction_kappa=0.0)
    q0, qd0 = np.array([0.1, -0.2, 0.02]), np.array([0.5, -0.3, 0.1])
    # the model stores its parameters in float32: the reference uses the same numbers
    kp, kd, db, eff, w0, damp, arm = (float(np.float32(x)) for x in (30.0, 1.0, 0.05, 20.0, 10.0, 0.2, 0.01))
    mass, bias = solver.dynamics_terms(q0, qd0)
    for tq in (np.array([0.3, -0.5, 0.1]), np.array([0.12, -0.21, 0.0])):  # outside / inside the dead band
        q = wp.array(np.stack([q0, np.zeros(N)])[:, None], dtype=wp.float64)
        qd = wp.array(np.stack([qd0, np.zeros(N)])[:, None], dtype=wp.float64)
        solver.rollout(q, qd, wp.array(tq[None, None], dtype=wp.float64), DT)
        tau = servo_torque(tq, q0, qd0, kp, kd, db, eff, w0)
        assert (np.abs(tau) < eff).all()  # neither clamp saturated: D = kd + U / w0
        h = mass[0] + np.diag(np.full(N, arm + DT * (kd + eff / w0 + damp)))
        expected = qd0 + DT * np.linalg.solve(h, tau - bias[0] - damp * qd0)
        np.testing.assert_allclose(qd.numpy()[1, 0], expected, rtol=1e-10, atol=1e-12)


STARTUP = 0.8
"""Startup torque of the tests that set one [N m]: against kp e_b = 30 * 0.15 = 4.5 N m, a term that matters."""


def test_startup_torque_one_step_matches_the_law(tmp_path):
    """One float64 step (the set-up of :func:`test_one_step_matches_the_law`) with a startup torque, against the
    numpy law: errors far outside the band (the full u0), half a tick outside it (half of u0) and inside (none)."""
    from wresdyn.robot.servo import STARTUP_RAMP

    robot = make_robot(tmp_path, joints="*", startup_torque=STARTUP)
    assert robot.servo.startup_torque.tolist() == [STARTUP] * N
    solver = SolverReplay(robot.build_model(1, "cpu"), dtype=wp.float64, friction_kappa=0.0)
    q0, qd0 = np.array([0.1, -0.2, 0.02]), np.array([0.5, -0.3, 0.1])
    kp, kd, db, eff, w0, damp, arm, u0 = (float(np.float32(x)) for x in (30.0, 1.0, 0.05, 20.0, 10.0, 0.2, 0.01,
                                                                         STARTUP))
    mass, bias = solver.dynamics_terms(q0, qd0)
    edge = q0 + np.array([1.0, -1.0, 1.0]) * (db + 0.5 * STARTUP_RAMP)
    for tq in (np.array([0.3, -0.5, 0.1]), edge, np.array([0.12, -0.21, 0.0])):
        q = wp.array(np.stack([q0, np.zeros(N)])[:, None], dtype=wp.float64)
        qd = wp.array(np.stack([qd0, np.zeros(N)])[:, None], dtype=wp.float64)
        solver.rollout(q, qd, wp.array(tq[None, None], dtype=wp.float64), DT)
        tau = servo_torque(tq, q0, qd0, kp, kd, db, eff, w0, startup_torque=u0)
        assert (np.abs(tau) < eff).all()
        h = mass[0] + np.diag(np.full(N, arm + DT * (kd + eff / w0 + damp)))
        expected = qd0 + DT * np.linalg.solve(h, tau - bias[0] - damp * qd0)
        np.testing.assert_allclose(qd.numpy()[1, 0], expected, rtol=1e-10, atol=1e-12)
    # half a tick past the band: half the startup torque on top of kp e_b
    np.testing.assert_allclose(servo_torque(edge, q0, 0.0, kp, 0.0, db, eff, 0.0, startup_torque=u0)
                               - servo_torque(edge, q0, 0.0, kp, 0.0, db, eff, 0.0), [0.5 * u0, -0.5 * u0, 0.5 * u0],
                               rtol=1e-6)


def test_startup_torque_gradient(tmp_path):
    """The startup torque's gradient against float64 central differences, on the servos (elbow a PD drive: not read)."""
    robot = make_robot(tmp_path, joints="[ss]*", startup_torque=STARTUP)
    problem = Problem(robot, *random_inputs(0, qd_scale=2.0, target_scale=0.2))
    grads = problem.gradients()
    entries = [("joint_servo_startup_torque", (k,)) for k in (0, 2, 3, 5)]
    check(problem, entries + [("joint_servo_deadband", (0,)), ("tq", (0, 0, 0))], grads)
    assert all(abs(grads[name][idx]) > 1e-6 for name, idx in entries)
    assert grads["joint_servo_startup_torque"][[1, 4]].tolist() == [0.0, 0.0]


STICTION = 1.0
"""Stiction of the tests that set one [N m], against the dry friction of 0.3: the bound at rest 1.3 N m."""


def test_stiction_one_step_is_the_friction_bound_of_the_law(tmp_path):
    """One float64 step with the soft dry friction: with stiction, below the stiction speed, the step of a robot
    whose dry friction is the law's bound (:func:`friction_bound` at the velocity before the step) without it;
    above that speed on every joint, the step without stiction, bit for bit."""
    from wresdyn.robot.servo import STICTION_SPEED, friction_bound

    robot = make_robot(tmp_path, joints="*", stiction=STICTION)
    assert robot.servo.stiction.tolist() == [STICTION] * N
    q0, tq = np.array([0.1, -0.2, 0.02]), np.array([0.3, -0.5, 0.1])
    fric, fs = float(np.float32(0.3)), float(np.float32(STICTION))

    def step(solver, qd0):
        q = wp.array(np.stack([q0, np.zeros(N)])[:, None], dtype=wp.float64)
        qd = wp.array(np.stack([qd0, np.zeros(N)])[:, None], dtype=wp.float64)
        solver.rollout(q, qd, wp.array(tq[None, None], dtype=wp.float64), DT)
        return qd.numpy()[1, 0]

    with_fs = SolverReplay(robot.build_model(1, "cpu"), dtype=wp.float64)
    plain = SolverReplay(make_robot(tmp_path, joints="*").build_model(1, "cpu"), dtype=wp.float64)
    slow = np.array([0.2, -0.5, 0.9]) * STICTION_SPEED
    bound = friction_bound(slow, fric, fs)
    np.testing.assert_allclose(bound, fric + fs * np.array([0.8, 0.5, 0.1]), rtol=1e-12)
    plain.parameters["joint_friction"].assign(bound)
    np.testing.assert_allclose(step(with_fs, slow), step(plain, slow), rtol=1e-12, atol=1e-14)
    plain.parameters["joint_friction"].assign(np.full(N, fric))
    fast = np.array([1.0, -1.5, 2.0]) * STICTION_SPEED
    np.testing.assert_array_equal(step(with_fs, fast), step(plain, fast))
    assert not np.allclose(step(with_fs, slow), step(plain, slow), rtol=1e-6)  # the stiction acts


def test_stiction_holds_a_joint_at_rest(tmp_path):
    """Hard Coulomb friction, the joints at rest inside their dead band (no servo torque) under gravity (2.2 N m on
    the shoulder, 3.0 N on the slide): a static friction of 4.3 holds them exactly, the sliding friction of 0.3
    alone does not."""
    q0, tq = np.array([0.6, -0.2, 0.05]), np.array([0.6, -0.2, 0.05])

    def step(robot):
        solver = SolverReplay(robot.build_model(1, "cpu"), dtype=wp.float64, friction_kappa=np.inf)
        _, bias = solver.dynamics_terms(q0, np.zeros(N))
        q = wp.array(np.stack([q0, np.zeros(N)])[:, None], dtype=wp.float64)
        qd = wp.zeros((2, 1, N), dtype=wp.float64)
        solver.rollout(q, qd, wp.array(tq[None, None], dtype=wp.float64), DT)
        return qd.numpy()[1, 0], np.abs(bias[0])

    v, gravity = step(make_robot(tmp_path, joints="*", stiction=4.0))
    assert (gravity[[0, 2]] > 2.0).all() and (gravity < 4.3 - 1.0).all(), gravity
    assert v.tolist() == [0.0] * N
    v, _ = step(make_robot(tmp_path, joints="*"))
    assert (np.abs(v[[0, 2]]) > 1e-3).all(), v


def test_stiction_gradient(tmp_path):
    """The stiction's gradient against float64 central differences, on the servos (elbow a PD drive: not read):
    joints starting near rest, so the bound rises above the friction on the first steps, where it slides."""
    from wresdyn.robot.servo import STICTION_SPEED

    robot = make_robot(tmp_path, joints="[ss]*", stiction=STICTION)
    q0, _, targets, jf = random_inputs(0, qd_scale=0.0, target_scale=0.2)
    qd0 = np.array([[0.3, 0.0, -0.5], [-0.6, 0.0, 0.2]]) * STICTION_SPEED
    problem = Problem(robot, q0, qd0, targets, 5.0 * jf)
    grads = problem.gradients()
    entries = [("joint_servo_stiction", (k,)) for k in (0, 2, 3, 5)]
    check(problem, entries + [("joint_friction", (0,)), ("qd0", (0, 0)), ("tq", (0, 0, 0))], grads)
    assert all(abs(grads[name][idx]) > 1e-6 for name, idx in entries)
    assert grads["joint_servo_stiction"][[1, 4]].tolist() == [0.0, 0.0]


@pytest.fixture(scope="module")
def servo_problem(tmp_path_factory):
    """Two of three joints servos (elbow a PD drive): sliding friction, unsaturated drives, targets 0.2 rad off so
    the error leaves the 0.05 rad dead band."""
    robot = make_robot(tmp_path_factory.mktemp("servo"), joints="[ss]*")
    assert robot.servo.mask.tolist() == [True, False, True]
    return Problem(robot, *random_inputs(0, qd_scale=2.0, target_scale=0.2))


SERVO_ENTRIES = [(name, (k,)) for name in ("joint_servo_deadband", "joint_servo_noload_speed", "joint_target_ke",
                                            "joint_target_kd", "joint_effort_limit", "joint_damping") for k in (0, 5)]
"""The servo fields and the reused ones on the shoulder (world 0) and the slide (world 1)."""


def test_servo_parameter_gradients(servo_problem):
    grads = servo_problem.gradients()
    check(servo_problem, SERVO_ENTRIES + [("joint_target_ke", (4,)), ("tq", (0, 0, 0)), ("q0", (1, 2))], grads)
    assert all(abs(grads[name][idx]) > 1e-6 for name, idx in SERVO_ENTRIES if name != "joint_effort_limit")
    # the elbow is a PD drive: its servo entries are not read
    assert grads["joint_servo_deadband"][[1, 4]].tolist() == [0.0, 0.0]
    assert grads["joint_servo_noload_speed"][[1, 4]].tolist() == [0.0, 0.0]


def test_saturated_servo_effort_gradient(tmp_path):
    """Targets 1 rad off with kp = 30 against a 2 N m stall torque: the duty saturates, the effort limit moves the
    torque both as U and through the torque-speed line U / w0."""
    robot = make_robot(tmp_path, effort=2.0, joints="*")
    q0, qd0, _, jf = random_inputs(2, qd_scale=0.5, target_scale=0.0)
    targets = np.broadcast_to(q0 + np.array([1.0, -1.0, 0.3]), (T, W, N)).copy()
    problem = Problem(robot, q0, qd0, targets, jf)
    grads = problem.gradients()
    check(problem, [("joint_effort_limit", (0,)), ("joint_effort_limit", (4,)), ("joint_servo_noload_speed", (0,))],
          grads)
    assert abs(grads["joint_effort_limit"][0]) > 1e-6


def test_goal_profile_torch_matches_numpy():
    """The bank's differentiable profile (torch, whole trajectories) is the MuJoCo robot's (numpy, step by step);
    a joint with a_max = 0 follows its command."""
    rng = np.random.default_rng(0)
    cmd = np.cumsum(rng.normal(scale=0.02, size=(300, 3)), 0)
    cmd[100:] += 0.5
    accel = np.array([39.0, 0.0, 10.0])
    dt = 0.002
    profile = GoalProfile(accel, dt, cmd[0])
    expected = np.array([profile(c) for c in cmd])
    table = torch.tensor(np.concatenate([cmd, cmd[:50]]))
    first = torch.tensor([0] * 300 + [300] * 50)
    a = torch.tensor(accel * dt * dt, requires_grad=True)
    goals = profile_goals(table, first, a)
    np.testing.assert_array_equal(goals[:300].detach().numpy(), expected)
    np.testing.assert_array_equal(goals[300:].detach().numpy(), expected[:50])
    np.testing.assert_array_equal(expected[:, 1], cmd[:, 1])
    assert np.abs(expected[:, 0] - cmd[:, 0]).max() > 0.1  # the 0.5 rad step is profiled
    goals.sum().backward()
    assert a.grad[1] == 0.0 and a.grad[0] != 0.0 and torch.isfinite(a.grad).all()


def test_physics_file_round_trip(tmp_path):
    robot = make_robot(tmp_path, joints="*")
    p = PhysicalParams.nominal(robot)
    p.save(tmp_path / "p.json")
    back = PhysicalParams.load(tmp_path / "p.json", robot)
    for f in ("deadband", "noload_speed", "goal_accel", "kp"):
        np.testing.assert_array_equal(getattr(back, f), getattr(p, f))
    old = json.loads((tmp_path / "p.json").read_text())
    for f in ("deadband", "noload_speed", "goal_accel"):
        del old[f]
    (tmp_path / "old.json").write_text(json.dumps(old))
    assert not PhysicalParams.load(tmp_path / "old.json", robot).deadband.any()


@pytest.mark.parametrize("fit, stiction, qd_start", [
    (("kp", "deadband", "noload_speed", "goal_accel", "startup_torque"), 0.0, 0.5),
    (("friction", "stiction"), STICTION, 0.02)])
def test_physics_model_gradients_reach_the_servo_fields(tmp_path, fit, stiction, qd_start):
    """The fit's path: PhysicsModel coordinates of kp and the servo fields -> the model arrays and the bank's
    goal profile (torch) -> :meth:`Simulator.step_diff` (float32); directional derivatives against central differences
    with the tolerance of ``test_physics.py``'s check (float32 steps). The stiction's from joints starting below the
    stiction speed (``qd_start`` [rad/s or m/s] on every joint), where it acts."""
    from wresdyn.sim import Simulator, TrajectoryBank
    from wresdyn.sim.physics import PhysicsModel

    robot = make_robot(tmp_path, joints="*", stiction=stiction)
    model = PhysicsModel(robot, fit=fit, dt=DT)
    b, h, t_len = 2, 8, 16
    sim = Simulator(robot, b, DT, solver="replay", requires_grad=True, param_grads=True)
    rng = np.random.default_rng(0)
    traj = []
    for i in range(b):  # a command step at sample 4: the profile is still accelerating in the window
        cmd = np.tile(rng.uniform(-0.1, 0.1, N), (t_len, 1))
        cmd[4:] += rng.uniform(0.2, 0.4, N) * np.array([1.0, -1.0, 0.2])
        traj.append(type("T", (), {"q": cmd.copy(), "qd": np.zeros_like(cmd), "qdd": np.zeros_like(cmd),
                                   "q_cmd": cmd})())
    q_ref = torch.as_tensor(rng.uniform(-0.2, 0.2, (b, h, N)), dtype=torch.float32)

    def loss():
        bank = TrajectoryBank(traj, sim.device, 0.0, model.goal_accel_steps().float())
        w = bank.window(torch.arange(b), torch.full((b,), 5), h)
        sim.set_physics(model())
        q, qd, total = w.q[:, 0], w.qd[:, 0] + qd_start, 0.0
        for k in range(h):
            q, qd = sim.step_diff(k, q, qd, w.target[:, k])
            total = total + ((q - q_ref[:, k]) ** 2).sum() + 0.01 * (qd ** 2).sum()
        return total

    params = {k: p for k, p in model.named_parameters() if p.requires_grad}
    assert set(params) == {f"u_{f}" for f in fit}
    model.zero_grad()
    loss().backward()
    check_directional_gradients(loss, params, {k: p.grad.clone() for k, p in params.items()}, eps=1e-2)


PARITY_TOL = 1.5e-4, 4e-4
"""Max |q| difference [rad or m] between SolverReplay with the true parameters and the MuJoCo servo robot at the same
step (dt = 2 ms, 1 s), on the servo joints and on the PD elbow: both integrate the law's velocity term implicitly,
so what is left is the two simulators' parity under dry friction (0.0003 rad on the humanoid's shipped data);
measured 6e-5 and 2.4e-4. A servo commanded to the edge of its dead band is not a fair case: there friction alone
decides whether it moves (a 0.05 m command against the 0.05 m band gave 0.011 m)."""


PARITY_TOL_STICTION = 4e-4
"""The servo joints' :data:`PARITY_TOL` with stiction [rad or m], measured 3.0e-4: where a joint breaks away, its
bound falls with its speed, which amplifies the two simulators' friction differences over the following steps."""


@pytest.mark.parametrize("startup, stiction", [(0.0, 0.0), (STARTUP, 0.0), (0.0, STICTION)])
def test_mujoco_servo_robot_runs_the_law_and_matches_the_replay(tmp_path, startup, stiction):
    """The MuJoCo "real" robot's servo joints (elbow a PD drive): the recorded actuator torque is the law
    (:func:`servo_torque`) at the recorded state and profiled goal, and SolverReplay replaying its true parameters
    follows the recording (a command step, so the profile, the band and the torque-speed line all act)."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.sim import replay_trajectories

    robot = make_robot(tmp_path, effort=5.0, joints="[ss]*", startup_torque=startup, stiction=stiction)
    rate = 1.0 / DT
    real = RealRobot(robot, Mismatch(), rate)
    cmd = np.tile(np.array([0.1, -0.2, 0.05]), (500, 1))
    cmd[50:] += np.array([0.4, 0.3, 0.15])
    cmd[300:] -= np.array([0.2, 0.1, 0.08])
    q, qd, tau = real.record(cmd, settle=0.0)
    profile = GoalProfile(np.where(robot.servo.mask, robot.servo.goal_accel, 0.0), DT, cmd[0])
    goal = np.array([profile(c) for c in cmd])
    law = servo_torque(goal, q, qd, 30.0, 1.0, 0.05, 5.0, 10.0, startup_torque=np.float32(startup))
    np.testing.assert_allclose(tau[:, [0, 2]], law[:, [0, 2]], rtol=1e-6, atol=1e-6)  # float32 model parameters
    assert np.abs(goal[:, 0] - cmd[:, 0]).max() > 0.05  # the profile acts

    truth = real.physics()
    np.testing.assert_allclose(truth.kp, 30.0, rtol=1e-6)
    assert truth.deadband.tolist() == [0.05, 0.0, 0.05]
    np.testing.assert_allclose(truth.startup_torque, [startup, 0.0, startup], rtol=1e-6)
    np.testing.assert_allclose(truth.stiction, [stiction, 0.0, stiction], rtol=1e-6)
    np.testing.assert_allclose(truth.friction, 0.3, rtol=1e-6)  # the sliding friction, not a step's bound
    traj = type("T", (), {"q": q, "qd": qd, "qdd": np.zeros_like(q), "q_cmd": cmd, "name": "step"})()
    rep = replay_trajectories(robot, [traj], rate, solver="replay", physics=truth)["residual"]
    err = np.abs(rep.q[0] - q).max(0)
    assert err[[0, 2]].max() < (PARITY_TOL_STICTION if stiction else PARITY_TOL[0]) and err[1] < PARITY_TOL[1], err
    if stiction:  # ... where the replay without the stiction is 40-400x further off
        plain = truth.copy()
        plain.stiction[:] = 0.0
        off = np.abs(replay_trajectories(robot, [traj], rate, solver="replay", physics=plain)["residual"].q[0] - q)
        assert off.max(0)[[0, 2]].min() > 0.005, off.max(0)  # measured 0.0115, 0.119
    assert np.abs(q - q[0]).max() > 0.3  # the joints moved
