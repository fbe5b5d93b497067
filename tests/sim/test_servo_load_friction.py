"""The servo's load friction (:mod:`wresdyn.robot.servo`: the gear train's dry friction grows by ``eta |tau|`` with
the drive torque it carries) in SolverReplay: one float64 step against the step of a robot whose dry friction is the
law's bound, a hold it makes under a load the plain friction lets slide, its gradient against central differences,
and the MuJoCo servo robot running the same law."""

import numpy as np
import warp as wp
from test_replay_gradients import DT, N, Problem, check, random_inputs
from test_servo import PARITY_TOL, make_robot

from wresdyn.robot.servo import friction_bound, servo_torque
from wresdyn.sim.solver_replay import SolverReplay

ETA = 0.4
"""Load friction of the tests [-]: against drive torques of 0.6-7 N m and the dry friction of 0.3 N m, a term that
dominates the bound."""


def _step(solver, q0, qd0, tq):
    q = wp.array(np.stack([q0, np.zeros(N)])[:, None], dtype=wp.float64)
    qd = wp.array(np.stack([qd0, np.zeros(N)])[:, None], dtype=wp.float64)
    solver.rollout(q, qd, wp.array(tq[None, None], dtype=wp.float64), DT)
    return qd.numpy()[1, 0]


def test_one_step_is_the_friction_bound_of_the_law(tmp_path):
    """One float64 step with the soft dry friction: the step of a robot without the load friction whose dry friction
    is the law's bound at the step's drive torque (:func:`servo_torque` at the state before it); the gains key."""
    robot = make_robot(tmp_path, joints="*", load_friction=ETA)
    assert robot.servo.load_friction.tolist() == [ETA] * N
    q0, qd0, tq = np.array([0.1, -0.2, 0.02]), np.array([0.5, -0.3, 0.1]), np.array([0.3, -0.5, 0.1])
    kp, kd, db, eff, w0, fric, eta = (float(np.float32(x)) for x in (30.0, 1.0, 0.05, 20.0, 10.0, 0.3, ETA))
    tau = servo_torque(tq, q0, qd0, kp, kd, db, eff, w0)
    assert (np.abs(tau) > 0.5).all() and (np.abs(tau) < eff).all()
    with_eta = SolverReplay(robot.build_model(1, "cpu"), dtype=wp.float64)
    plain = SolverReplay(make_robot(tmp_path, joints="*").build_model(1, "cpu"), dtype=wp.float64)
    free = _step(plain, q0, qd0, tq)
    plain.parameters["joint_friction"].assign(friction_bound(qd0, fric, 0.0, eta, tau))
    np.testing.assert_allclose(_step(with_eta, q0, qd0, tq), _step(plain, q0, qd0, tq), rtol=1e-12, atol=1e-14)
    assert not np.allclose(_step(with_eta, q0, qd0, tq), free, rtol=1e-6)  # the load friction acts


def test_load_friction_holds_a_loaded_joint(tmp_path):
    """Hard Coulomb friction, the joints at rest past their dead bands, the servos pushing with 0.6-4.5 N m against
    gravity, 0.7-1.5 N m more than it: the plain friction of 0.3 N m lets them slide, a load friction as large as the
    drive torque (a self-locking gear train) holds them exactly."""
    q0 = np.array([0.6, -0.2, 0.05])
    tq = q0 + np.array([0.15, -0.07, 0.2])

    def step(robot):
        solver = SolverReplay(robot.build_model(1, "cpu"), dtype=wp.float64, friction_kappa=np.inf)
        _, bias = solver.dynamics_terms(q0, np.zeros(N))
        return _step(solver, q0, np.zeros(N), tq), bias[0]

    v, gravity = step(make_robot(tmp_path, joints="*", load_friction=1.0))
    tau = servo_torque(tq, q0, 0.0, 30.0, 1.0, 0.05, 20.0, 10.0)
    assert (np.abs(tau - gravity) > 0.6).all() and (np.abs(tau - gravity) < 0.3 + np.abs(tau) - 0.1).all()
    assert v.tolist() == [0.0] * N
    v, _ = step(make_robot(tmp_path, joints="*"))
    assert (np.abs(v) > 1e-3).all(), v


def test_load_friction_gradient(tmp_path):
    """The load friction's gradient against float64 central differences, on the servos (elbow a PD drive: not
    read): targets 0.2 rad off, so the drives carry torque while the joints slide."""
    robot = make_robot(tmp_path, joints="[ss]*", load_friction=ETA)
    problem = Problem(robot, *random_inputs(0, qd_scale=2.0, target_scale=0.2))
    grads = problem.gradients()
    entries = [("joint_servo_load_friction", (k,)) for k in (0, 2, 3, 5)]
    check(problem, entries + [("joint_friction", (0,)), ("joint_target_ke", (0,)), ("tq", (0, 0, 0))], grads)
    assert all(abs(grads[name][idx]) > 1e-6 for name, idx in entries)
    assert grads["joint_servo_load_friction"][[1, 4]].tolist() == [0.0, 0.0]


def test_mujoco_servo_robot_runs_the_load_friction(tmp_path):
    """The MuJoCo "real" robot's servo joints with the load friction: SolverReplay replaying its true parameters
    follows the recording (a command step that loads the drives), where the replay without the term does not."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.sim import replay_trajectories

    robot = make_robot(tmp_path, effort=5.0, joints="[ss]*", load_friction=ETA)
    real = RealRobot(robot, Mismatch(), 1.0 / DT)
    cmd = np.tile(np.array([0.1, -0.2, 0.05]), (500, 1))
    cmd[50:] += np.array([0.4, 0.3, 0.15])
    cmd[300:] -= np.array([0.2, 0.1, 0.08])
    q, qd, _ = real.record(cmd, settle=0.0)
    truth = real.physics()
    np.testing.assert_allclose(truth.load_friction, [ETA, 0.0, ETA], rtol=1e-6)
    np.testing.assert_allclose(truth.friction, 0.3, rtol=1e-6)  # the sliding friction, not a step's bound
    traj = type("T", (), {"q": q, "qd": qd, "qdd": np.zeros_like(q), "q_cmd": cmd, "name": "step"})()
    err = np.abs(replay_trajectories(robot, [traj], 1.0 / DT, solver="replay", physics=truth)["residual"].q[0] - q)
    assert err.max(0)[[0, 2]].max() < PARITY_TOL[0] and err.max(0)[1] < PARITY_TOL[1], err.max(0)
    plain = truth.copy()
    plain.load_friction[:] = 0.0
    off = np.abs(replay_trajectories(robot, [traj], 1.0 / DT, solver="replay", physics=plain)["residual"].q[0] - q)
    assert off.max(0)[[0, 2]].min() > 10 * PARITY_TOL[0], off.max(0)
