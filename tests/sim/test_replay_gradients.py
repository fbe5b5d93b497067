"""SolverReplay's gradients w.r.t. its own parameters against central finite differences (float64).

The milestone this serves is differentiable system identification: per joint the drive gains, armature,
viscous damping, dry friction and effort limit, per link the mass, centre of mass and inertia, each read
from the Newton model's arrays. A 3-DoF robot (skewed axes, full inertia tensors, a prismatic joint) in
two worlds with different parameters runs 8 steps; the loss weighs the final state. float64 kernels read
float64 copies of the parameters (``SolverReplay.parameters``), so the differences are perturbed there.
The float32 path (the model's own arrays, ``step`` and ``rollout``) is checked against the float64 one.
"""

import math

import numpy as np
import pytest
import warp as wp
from test_solver_replay import TRI_URDF, step_tape

from wresdyn.robot.description import load_robot
from wresdyn.sim.solver_replay import SolverReplay

DT = 0.002
T, W, N = 8, 2, 3

EPS = 1e-5
"""Relative finite-difference step h (of the parameter, or of 0.01 for centres of mass and inertias, 1 for the
rest, when larger): float64 truncation error ~EPS^2 relative, round-off ~1e-16 |loss| / h <= 1e-9."""
RTOL, ATOL = 1e-6, 1e-8
"""Central differences in float64 agree with the Tape to ~1e-9 where no kink (friction or effort saturation
switching, a limit) lies within +-h; these leave a 10-100x margin and catch any missing or doubled term."""


def make_robot(tmp_path, friction, effort):
    path = tmp_path / "tri.urdf"
    path.write_text(TRI_URDF)
    gains = {"joint": [{"match": "*", "kp": 30.0, "kd": 1.0, "armature": 0.01, "damping": 0.2,
                        "friction": friction, "effort": effort}]}
    return load_robot(path, gains=gains)


def two_worlds(robot):
    """A model with gradients whose world 1 is another robot: heavier links, shifted centres of mass, stiffer
    drives, more armature."""
    model = robot.build_model(W, "cpu", requires_grad=True)
    for name, change in (("body_mass", lambda a: a * 1.3), ("body_com", lambda a: a + 0.01),
                         ("joint_target_ke", lambda a: a * 1.2), ("joint_armature", lambda a: a * 1.5)):
        arr = getattr(model, name)
        a = arr.numpy()
        a[len(a) // 2:] = change(a[len(a) // 2:])
        arr.assign(a)
    return model


class Problem:
    """A float64 rollout of two different worlds and its loss; parameters perturbed in ``solver.parameters``."""

    def __init__(self, robot, q0, qd0, targets, joint_f, seed=0, **solver_kw):
        self.solver = SolverReplay(two_worlds(robot), dtype=wp.float64, **solver_kw)
        self.inputs = {"q0": q0, "qd0": qd0, "tq": targets, "jf": joint_f}
        self.weights = np.random.default_rng(seed).normal(size=(W, N))

    def arrays(self, inputs, grad):
        q, qd = np.zeros((T + 1, W, N)), np.zeros((T + 1, W, N))
        q[0], qd[0] = inputs["q0"], inputs["qd0"]
        return [wp.array(a, dtype=wp.float64, requires_grad=grad) for a in (q, qd, inputs["tq"], inputs["jf"])]

    def loss(self, inputs=None):
        q, qd, tq, jf = self.arrays(inputs or self.inputs, False)
        self.solver.rollout(q, qd, tq, DT, joint_f=jf)
        return float((q.numpy()[T] * self.weights).sum() + 0.1 * (qd.numpy()[T] * self.weights).sum())

    def gradients(self):
        """Tape gradients of the loss: the inputs' and every parameter array's."""
        for a in self.solver.parameters.values():
            if a.requires_grad:
                a.grad.zero_()
        q, qd, tq, jf = self.arrays(self.inputs, True)
        tape = wp.Tape()
        with tape:
            self.solver.rollout(q, qd, tq, DT, joint_f=jf)
        seed_q, seed_qd = np.zeros((T + 1, W, N)), np.zeros((T + 1, W, N))
        seed_q[T], seed_qd[T] = self.weights, 0.1 * self.weights
        tape.backward(grads={q: wp.array(seed_q, dtype=wp.float64), qd: wp.array(seed_qd, dtype=wp.float64)})
        out = {"q0": q.grad.numpy()[0], "qd0": qd.grad.numpy()[0], "tq": tq.grad.numpy(), "jf": jf.grad.numpy()}
        out.update({name: a.grad.numpy() for name, a in self.solver.parameters.items() if a.requires_grad})
        return out

    def fd_param(self, name, idx):
        arr = self.solver.parameters[name]
        base = arr.numpy().copy()  # a CPU array's numpy() is a view of its memory
        h = EPS * max(abs(base[idx]), 1e-2 if name in ("body_inertia", "body_com") else 1.0)
        values = []
        for sign in (1.0, -1.0):
            a = base.copy()
            a[idx] += sign * h
            arr.assign(a)
            values.append(self.loss())
        arr.assign(base)
        return (values[0] - values[1]) / (2 * h)

    def fd_input(self, key, idx):
        h = EPS * max(abs(self.inputs[key][idx]), 1.0)
        values = []
        for sign in (1.0, -1.0):
            inputs = {k: v.copy() for k, v in self.inputs.items()}
            inputs[key][idx] += sign * h
            values.append(self.loss(inputs))
        return (values[0] - values[1]) / (2 * h)


def random_inputs(seed, qd_scale, target_scale):
    rng = np.random.default_rng(seed)
    q0 = np.array([[0.3, -0.2, 0.05], [0.1, 0.4, -0.1]])
    return (q0, rng.normal(scale=qd_scale, size=(W, N)), q0 + rng.normal(scale=target_scale, size=(T, W, N)),
            rng.normal(scale=0.5, size=(T, W, N)))


# the bodies of one world: 0 base (fixed), 1 upper, 2 lower, 3 slider; the second world's start at 4
BODY_ENTRIES = [
    ("body_mass", (1,)), ("body_mass", (6,)), ("body_mass", (3,)),
    ("body_com", (1, 0)), ("body_com", (2, 2)), ("body_com", (6, 1)), ("body_com", (7, 0)),
    ("body_inertia", (1, 1, 1)), ("body_inertia", (2, 1, 1)), ("body_inertia", (6, 2, 2)), ("body_inertia", (7, 1, 1)),
    ("body_inertia", (2, 2, 0)), ("body_inertia", (6, 0, 1)),
]
"""Masses, centres of mass and diagonal and off-diagonal inertia entries that move the loss, in both worlds.
An off-diagonal entry alone moves half the symmetrised inertia (the kernel reads (I + I^T) / 2)."""
INERT_BODY_ENTRIES = [("body_com", (5, 1)), ("body_com", (3, 1)), ("body_inertia", (1, 0, 0)),
                      ("body_inertia", (1, 0, 1)), ("body_inertia", (7, 1, 2)), ("body_inertia", (3, 2, 2))]
"""Entries the dynamics cannot see: the upper link and the slider only turn about the shoulder's y axis (the
slider's frame is turned about y too), so their centre of mass along y and every inertia entry but I_yy
leave the loss unchanged; their gradient must be 0 (not just small)."""
JOINT_ENTRIES = [(name, (k,)) for name in ("joint_target_ke", "joint_target_kd", "joint_armature", "joint_damping")
                 for k in (0, 4)]
"""Drive gains, armature and damping of a revolute joint in world 0 and of the other revolute in world 1."""
INPUT_ENTRIES = [("q0", (0, 0)), ("q0", (1, 2)), ("qd0", (0, 1)), ("qd0", (1, 0)), ("tq", (0, 0, 0)),
                 ("tq", (5, 1, 2)), ("jf", (0, 0, 1)), ("jf", (7, 1, 0))]


@pytest.fixture(scope="module")
def sliding(tmp_path_factory):
    """Fast joints (|qd| ~ 2 rad/s) against mu = 0.3 N m: friction slides all along, the drives are not saturated."""
    robot = make_robot(tmp_path_factory.mktemp("sliding"), friction=0.3, effort=1e3)
    return Problem(robot, *random_inputs(0, qd_scale=2.0, target_scale=0.2))


def check(problem, entries, grads):
    for name, idx in entries:
        fd = problem.fd_param(name, idx) if name in problem.solver.parameters else problem.fd_input(name, idx)
        assert grads[name][idx] == pytest.approx(fd, rel=RTOL, abs=ATOL), (name, idx)


def test_body_parameter_gradients(sliding):
    grads = sliding.gradients()
    check(sliding, BODY_ENTRIES + INERT_BODY_ENTRIES, grads)
    assert all(abs(grads[name][idx]) > 1e-4 for name, idx in BODY_ENTRIES)
    assert all(abs(grads[name][idx]) < 1e-15 for name, idx in INERT_BODY_ENTRIES)


def test_joint_parameter_and_input_gradients(sliding):
    grads = sliding.gradients()
    check(sliding, JOINT_ENTRIES + INPUT_ENTRIES, grads)


def test_friction_gradient_sliding_and_stuck(sliding, tmp_path):
    """Sliding, the friction torque is -mu sign(v): d loss / d mu is the finite difference. Stuck (mu above
    every torque, from rest), the joint creeps at tau / (kappa H_ii), or stands still with hard Coulomb
    friction, whatever mu is: the gradient is exactly 0."""
    grads = sliding.gradients()
    check(sliding, [("joint_friction", (0,)), ("joint_friction", (4,)), ("joint_friction", (5,))], grads)
    assert min(abs(grads["joint_friction"][k]) for k in (0, 4, 5)) > 1e-6

    hard = Problem(make_robot(tmp_path, friction=0.3, effort=1e3), *random_inputs(0, qd_scale=2.0, target_scale=0.2),
                   friction_kappa=math.inf)
    check(hard, [("joint_friction", (0,)), ("joint_friction", (4,)), ("joint_friction", (5,))], hard.gradients())

    for kappa in (None, math.inf):
        robot = make_robot(tmp_path, friction=50.0, effort=1e3)
        kw = {} if kappa is None else {"friction_kappa": kappa}
        stuck = Problem(robot, *random_inputs(1, qd_scale=0.0, target_scale=0.2), **kw)
        grads = stuck.gradients()
        assert not grads["joint_friction"].any()
        for k in (0, 1, 5):
            assert abs(stuck.fd_param("joint_friction", (k,))) < ATOL
        if kappa is None:  # the rest of the dynamics still has gradients through the creeping joints
            check(stuck, [("joint_target_ke", (0,)), ("body_mass", (2,)), ("tq", (0, 0, 0))], grads)


def test_frictionless_worlds_skip_the_solve_unless_friction_grad(tmp_path):
    """At mu = 0 everywhere the solve returns v* exactly, so skipping it (``friction_grad=False``, what residual
    learning runs) leaves the loss and every gradient but joint_friction's bit for bit as they are with the solve
    (``friction_grad=True``, identification); joint_friction's is then 0. With the solve, the gradient at mu = 0 is
    the one-sided difference towards mu > 0 (mu < 0 has no meaning), sliding joints' -sign(v) terms."""
    robot = make_robot(tmp_path, friction=0.0, effort=1e3)
    inputs = random_inputs(0, qd_scale=2.0, target_scale=0.2)
    skip, solve = Problem(robot, *inputs, friction_grad=False), Problem(robot, *inputs, friction_grad=True)
    assert skip.loss() == solve.loss()
    g_skip, g_solve = skip.gradients(), solve.gradients()
    for name, g in g_skip.items():
        if name != "joint_friction":
            assert np.array_equal(g, g_solve[name]), name
    assert not g_skip["joint_friction"].any()
    arr, base = solve.solver.parameters["joint_friction"], solve.loss()
    for k in (0, 4, 5):
        h = 1e-6  # one-sided: truncation error ~h * curvature
        a = arr.numpy().copy()
        a[k] = h
        arr.assign(a)
        fd = (solve.loss() - base) / h
        a[k] = 0.0
        arr.assign(a)
        assert abs(g_solve["joint_friction"][k]) > 1e-4  # measured 4e-4, 0.018, 1.3e-3
        assert g_solve["joint_friction"][k] == pytest.approx(fd, rel=1e-5), k  # measured 4e-8 relative


def test_effort_limit_gradient_when_saturated(tmp_path):
    """Targets ~1 rad away with kp = 30 ask for ~30 N m against a 2 N m limit: the drive torque is the limit, so
    d loss / d effort is the finite difference (and kp, kd have no effect)."""
    robot = make_robot(tmp_path, friction=0.3, effort=2.0)
    q0, qd0, _, jf = random_inputs(2, qd_scale=0.5, target_scale=0.0)
    targets = np.broadcast_to(q0 + np.array([1.0, -1.0, 0.3]), (T, W, N)).copy()  # kp * offset >= 9 N m > 2 N m
    problem = Problem(robot, q0, qd0, targets, jf)
    grads = problem.gradients()
    check(problem, [("joint_effort_limit", (0,)), ("joint_effort_limit", (4,)), ("joint_effort_limit", (2,))],
          grads)
    assert abs(grads["joint_effort_limit"][0]) > 1e-6
    assert grads["joint_target_ke"][0] == 0.0


def test_float32_step_and_rollout_reach_the_model_arrays(tmp_path):
    """float32: a Tape over step() and one over rollout() put the same gradients into model.body_mass.grad etc.,
    and they agree with the float64 ones (float32 round-off through 8 steps, ~1e-5 relative)."""
    robot = make_robot(tmp_path, friction=0.3, effort=1e3)
    q0, qd0, tq, jf = random_inputs(0, qd_scale=2.0, target_scale=0.2)
    reference = Problem(robot, q0, qd0, tq, jf)
    expected = reference.gradients()
    weights = reference.weights

    model = two_worlds(robot)
    solver = SolverReplay(model)
    names = ("body_mass", "body_com", "body_inertia", "joint_target_ke", "joint_friction")

    def grads():
        out = {name: getattr(model, name).grad.numpy().copy() for name in names}
        for name in names:
            getattr(model, name).grad.zero_()
        return out

    seed_q, seed_qd = (weights.astype(np.float32), (0.1 * weights).astype(np.float32))
    q = wp.array(np.concatenate([q0[None], np.zeros((T, W, N))]).astype(np.float32), requires_grad=True)
    qd = wp.array(np.concatenate([qd0[None], np.zeros((T, W, N))]).astype(np.float32), requires_grad=True)
    tqa, jfa = wp.array(tq.astype(np.float32), requires_grad=True), wp.array(jf.astype(np.float32), requires_grad=True)
    tape = wp.Tape()
    with tape:
        solver.rollout(q, qd, tqa, DT, joint_f=jfa)
    sq, sqd = np.zeros((T + 1, W, N), np.float32), np.zeros((T + 1, W, N), np.float32)
    sq[T], sqd[T] = seed_q, seed_qd
    tape.backward(grads={q: wp.array(sq), qd: wp.array(sqd)})
    via_rollout = grads()

    states, controls, tape = step_tape(solver, q0, tq, jf, qd0)
    tape.backward(grads={states[T].joint_q: wp.array(seed_q.ravel()), states[T].joint_qd: wp.array(seed_qd.ravel())})
    via_step = grads()
    for name in names:
        scale = np.abs(expected[name]).max()
        assert scale > 1e-4, name
        # same adjoint kernel on trajectories that differ by float32 round-off of the fused forward
        assert np.abs(via_step[name] - via_rollout[name]).max() <= 1e-4 * scale, name
        assert np.abs(via_rollout[name] - expected[name]).max() <= 1e-3 * scale, name
