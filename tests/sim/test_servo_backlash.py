"""Backlash and encoder zero offset of the servo law (:mod:`wresdyn.robot.servo`) in SolverReplay: one float64 step
against the numpy law (outside the play, inside it where the link swings free), the gradients of both fields against
central differences, their default of 0 giving the law without them, and the gains keys."""

import numpy as np
import pytest
import warp as wp
from test_replay_gradients import DT, N, Problem, check, random_inputs
from test_servo import make_robot

from wresdyn.errors import RobotError
from wresdyn.robot.servo import STARTUP_RAMP, play, read_servo, servo_torque
from wresdyn.sim.solver_replay import SolverReplay

BACKLASH, OFFSET = 0.03, 0.02
"""Play half-width and encoder offset of the tests [rad]: against the 0.05 rad dead band and 0.2 rad targets."""


def test_gains_keys_and_signs(tmp_path):
    robot = make_robot(tmp_path, joints="elbow", backlash=BACKLASH, encoder_offset=-OFFSET)
    assert robot.servo.backlash.tolist() == [0.0, BACKLASH, 0.0]
    assert robot.servo.encoder_offset.tolist() == [0.0, -OFFSET, 0.0]  # signed
    model = robot.build_model(2, "cpu")
    assert model.joint_servo_encoder_offset.numpy().tolist() == pytest.approx([0, -OFFSET, 0] * 2)
    with pytest.raises(RobotError, match="backlash"):
        read_servo({"joint": [{"match": "*", "drive": "servo", "backlash": -0.1}]}, ["a"], [1.0])


def test_numpy_law_defaults_and_play():
    """0 for both: the law without them, exactly; inside the play no torque at all (no loop, no back-EMF); past it
    the drive on the error less the play, in mesh a tick past the edge."""
    rng = np.random.default_rng(0)
    e, qd = rng.uniform(-0.3, 0.3, 64), rng.uniform(-2, 2, 64)
    args = (5.0, 0.1, 0.004, 1.9, 5.4)
    plain = servo_torque(e, 0.0, qd, *args, startup_torque=0.2)
    assert np.array_equal(servo_torque(e, 0.0, qd, *args, startup_torque=0.2, backlash=0.0, encoder_offset=0.0),
                          plain)
    with_off = servo_torque(e, 0.0, qd, *args, encoder_offset=OFFSET)
    np.testing.assert_allclose(with_off, servo_torque(e - OFFSET, 0.0, qd, *args), rtol=0, atol=1e-15)
    inside = servo_torque(np.array([0.01, -0.029]), 0.0, np.array([1.0, -1.0]), *args, backlash=BACKLASH)
    assert inside.tolist() == [0.0, 0.0]
    far = np.array([0.2, -0.25])
    np.testing.assert_allclose(servo_torque(far, 0.0, qd[:2], *args, backlash=BACKLASH),
                               servo_torque(far - np.sign(far) * BACKLASH, 0.0, qd[:2], *args), rtol=1e-12)
    _, g = play(np.array([BACKLASH + 0.5 * STARTUP_RAMP]), BACKLASH)
    assert g[0] == pytest.approx(0.5)


def test_one_step_matches_the_law(tmp_path):
    """One float64 step without dry friction against the numpy law and the solver's step ``H (v - qd) = dt (tau - c
    - d qd)``: the shoulder past the play (the drive's D in ``H``), the elbow inside it (no drive, only the passive
    damping), the slide past it with the offset moving its error."""
    robot = make_robot(tmp_path, joints="*", backlash=BACKLASH, encoder_offset=OFFSET)
    solver = SolverReplay(robot.build_model(1, "cpu"), dtype=wp.float64, friction_kappa=0.0)
    q0, qd0 = np.array([0.1, -0.2, 0.02]), np.array([0.5, -0.3, 0.1])
    kp, kd, db, eff, w0, damp, arm, bl, off = (float(np.float32(x)) for x in (30.0, 1.0, 0.05, 20.0, 10.0, 0.2, 0.01,
                                                                              BACKLASH, OFFSET))
    tq = np.array([0.3, -0.2 + OFFSET + 0.01, 0.2])
    mass, bias = solver.dynamics_terms(q0, qd0)
    q = wp.array(np.stack([q0, np.zeros(N)])[:, None], dtype=wp.float64)
    qd = wp.array(np.stack([qd0, np.zeros(N)])[:, None], dtype=wp.float64)
    solver.rollout(q, qd, wp.array(tq[None, None], dtype=wp.float64), DT)
    tau = servo_torque(tq, q0, qd0, kp, kd, db, eff, w0, backlash=bl, encoder_offset=off)
    assert tau[1] == 0.0 and abs(tau[0]) > 1.0 and abs(tau[2]) > 1.0 and (np.abs(tau) < eff).all()
    d = np.array([kd + eff / w0, 0.0, kd + eff / w0]) + damp
    h = mass[0] + np.diag(arm + DT * d)
    expected = qd0 + DT * np.linalg.solve(h, tau - bias[0] - damp * qd0)
    np.testing.assert_allclose(qd.numpy()[1, 0], expected, rtol=1e-10, atol=1e-12)


@pytest.mark.parametrize("field", ["joint_servo_backlash", "joint_servo_encoder_offset"])
def test_gradients(tmp_path, field):
    """The two fields' gradients against float64 central differences, on the servos (elbow a PD drive: not read);
    targets 0.2 rad off, so the errors leave the play and the dead band."""
    robot = make_robot(tmp_path, joints="[ss]*", backlash=BACKLASH, encoder_offset=OFFSET)
    problem = Problem(robot, *random_inputs(0, qd_scale=2.0, target_scale=0.2))
    grads = problem.gradients()
    entries = [(field, (k,)) for k in (0, 2, 3, 5)]
    check(problem, entries + [("tq", (0, 0, 0))], grads)
    assert all(abs(grads[name][idx]) > 1e-6 for name, idx in entries)
    assert grads[field][[1, 4]].tolist() == [0.0, 0.0]
