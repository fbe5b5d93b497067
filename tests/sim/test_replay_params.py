"""SolverReplay reads link inertias from the Newton model arrays, per world, and keeps its kernel cache safe.

- the compiled structure (tree digest) does not depend on masses or inertias;
- per-world masses, centres of mass and inertias, welded bodies included: M(q) and c(q, qd) against MuJoCo C
  built from the same numbers (float64 kernels: the model's float32 parameters limit the agreement);
- edits take effect without recompiling, zeros of the robot file made non-zero included: one module per structure.
"""

import dataclasses

import mujoco
import newton
import numpy as np
import pytest
import warp as wp
from test_solver_replay import TRI_URDF

from wresdyn.robot.description import load_robot
from wresdyn.robot.mujoco_model import build_mujoco
from wresdyn.sim.solver_replay import SolverReplay
from wresdyn.sim.solver_replay.tree import tree_from_model

DT = 0.002

TOL = 2e-7
"""Relative, float64 kernels vs MuJoCo on M and c: Newton stores the parameters in float32 (relative 6e-8)."""

WELDED_URDF = TRI_URDF.replace("</robot>", """  <link name="tool"><inertial>
    <origin xyz="0.03 -0.02 -0.05" rpy="0.3 0 0.2"/><mass value="0.4"/>
    <inertia ixx="0.0009" iyy="0.0007" izz="0.0004" ixy="0.0001" ixz="0" iyz="0.00005"/></inertial></link>
  <joint name="wrist_weld" type="fixed"><parent link="lower"/><child link="tool"/>
    <origin xyz="0.02 0.0 -0.25" rpy="0.0 0.4 -0.3"/></joint>
</robot>
""")
"""The 3-DoF test robot with a tool welded to the lower link by a rotated, offset fixed joint."""


@pytest.fixture(scope="module")
def robots(tmp_path_factory):
    out = {}
    for name, text in (("tri", TRI_URDF), ("welded", WELDED_URDF)):
        path = tmp_path_factory.mktemp(name) / f"{name}.urdf"
        path.write_text(text)
        out[name] = load_robot(path, gains={"joint": [{"match": "*", "kp": 30.0, "kd": 1.0, "armature": 0.01}]})
    return out


def perturbed(robot, seed):
    """``robot`` with other link masses, centres of mass and (full, symmetric positive) inertias."""
    rng = np.random.default_rng(seed)
    nb = robot.n_bodies
    rot = np.linalg.qr(rng.normal(size=(nb, 3, 3)))[0]
    inertia = rot @ (robot.body_inertia * rng.uniform(0.7, 1.4, (nb, 1, 1))) @ rot.transpose(0, 2, 1)
    return dataclasses.replace(robot, body_mass=robot.body_mass * rng.uniform(0.6, 1.5, nb),
                               body_com=robot.body_com + rng.normal(scale=0.03, size=(nb, 3)),
                               body_inertia=0.5 * (inertia + inertia.transpose(0, 2, 1)))


def set_world(model, world, robot):
    """Write ``robot``'s inertial parameters into world ``world`` of ``model``."""
    nb = robot.n_bodies
    sl = slice(world * nb, (world + 1) * nb)
    for name, value in (("body_mass", robot.body_mass), ("body_com", robot.body_com),
                        ("body_inertia", robot.body_inertia)):
        arr = getattr(model, name)
        full = arr.numpy()
        full[sl] = value
        arr.assign(full)


def assert_terms_match_mujoco(solver, world, robot):
    rng = np.random.default_rng(world)
    q, qd = rng.uniform(-0.5, 0.5, (3, robot.n_dof)), rng.uniform(-2.0, 2.0, (3, robot.n_dof))
    M, c = solver.dynamics_terms(q, qd, world=world)
    m = build_mujoco(robot, DT)
    d = mujoco.MjData(m)
    for i in range(len(q)):
        d.qpos[:], d.qvel[:] = q[i], qd[i]
        mujoco.mj_forward(m, d)
        full = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, full)
        full -= np.diag(robot.armature)
        assert np.abs(M[i] - full).max() <= TOL * max(1.0, np.abs(full).max())
        assert np.abs(c[i] - d.qfrc_bias).max() <= TOL * max(1.0, np.abs(d.qfrc_bias).max())


# ---------------------------------------------------------------- structure vs parameters


def test_digest_ignores_inertial_parameters(robots):
    model = robots["welded"].build_model(2, "cpu")
    digest = tree_from_model(model).digest()
    set_world(model, 1, perturbed(robots["welded"], 0))
    tree = tree_from_model(model)  # worlds with different inertias are still one robot
    assert tree.digest() == digest
    tool = robots["welded"].body_names.index("tool")
    lower = robots["welded"].body_names.index("lower")
    assert tree.body_dof[tool] == tree.body_dof[lower] >= 0 and not np.allclose(tree.pos_db[tool], 0.0)


@pytest.mark.parametrize("name", ["tri", "welded"])
def test_per_world_inertias_match_mujoco(robots, name):
    """World 1 gets other masses, centres of mass and inertias; each world matches MuJoCo built from its own."""
    robot = robots[name]
    model = robot.build_model(2, "cpu")
    solver = SolverReplay(model, dtype=wp.float64)
    kernels = solver.kernels
    other = perturbed(robot, 1)
    set_world(model, 1, other)
    solver.notify_model_changed(newton.ModelFlags.BODY_INERTIAL_PROPERTIES)  # float64 copies the arrays again
    assert solver.kernels is kernels, "an inertia edit must not recompile"
    assert_terms_match_mujoco(solver, 0, robot)
    assert_terms_match_mujoco(solver, 1, other)


def test_float32_edits_are_live_and_never_recompile(robots):
    """float32 reads the model arrays at every launch: a mass edit, a product of inertia and a friction that were 0
    in the robot file take effect without notify_model_changed, on the same module; a solver built on the edited
    model loads that module too and steps to the same bits."""
    robot = robots["tri"]
    model = robot.build_model(1, "cpu")
    solver = SolverReplay(model)
    kernels = solver.kernels

    def step(s):
        state, out = model.state(), model.state()
        state.joint_q.assign(np.array([0.3, -0.4, 0.05], np.float32))
        state.joint_qd.assign(np.array([1.0, -0.5, 0.2], np.float32))
        s.step(state, out, None, None, DT)
        return out.joint_qd.numpy()

    before = step(solver)
    mass = model.body_mass.numpy()
    mass[1:] *= 1.5
    model.body_mass.assign(mass)
    after_mass = step(solver)
    assert np.abs(after_mass - before).max() > 1e-3

    inertia = model.body_inertia.numpy()
    b, i, j = np.argwhere(inertia[1:] == 0.0)[0] + np.array([1, 0, 0])  # a product of inertia the file has as 0
    inertia[b, i, j] = inertia[b, j, i] = 2e-4
    model.body_inertia.assign(inertia)
    after_inertia = step(solver)
    assert not np.array_equal(after_inertia, after_mass)

    assert not model.joint_friction.numpy().any()
    model.joint_friction.assign(np.full(model.joint_dof_count, 0.5, np.float32))
    after_friction = step(solver)
    assert np.abs(after_friction - after_inertia).max() > 1e-3
    solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_PROPERTIES | newton.ModelFlags.BODY_INERTIAL_PROPERTIES)
    assert solver.kernels is kernels

    reference = SolverReplay(model)
    assert reference.kernels is kernels, "the module depends on the robot's structure, not its values"
    assert np.array_equal(step(reference), after_friction)


def test_friction_branch_gives_the_same_step_in_both_modules(robots):
    """The kernels run the friction solve only in worlds with friction (a run-time branch), or everywhere with
    ``friction_grad``. One launch with a frictionless world and a world with friction: both modules, the branch
    taken or forced, give the same step, and the friction acts in its world."""
    robot = robots["tri"]
    model = robot.build_model(2, "cpu")
    friction = np.zeros(model.joint_dof_count, np.float32)
    friction[model.joint_dof_count // 2:] = 0.5  # [N*m], world 1 only
    model.joint_friction.assign(friction)
    forward, adjoint = SolverReplay(model), SolverReplay(model, requires_grad=True)
    assert forward.kernels is not adjoint.kernels

    def step(solver):
        state, out = model.state(), model.state()
        state.joint_q.assign(np.tile(np.array([0.3, -0.4, 0.05], np.float32), 2))
        state.joint_qd.assign(np.tile(np.array([1.0, -0.5, 0.2], np.float32), 2))
        solver.step(state, out, None, None, DT)
        return out.joint_qd.numpy().reshape(2, -1)

    a, b = step(forward), step(adjoint)
    adjoint.friction_grad = True
    assert np.array_equal(a, b) and np.array_equal(a, step(adjoint))  # without friction the solve returns v* exactly
    assert np.abs(a[1] - a[0]).max() > 0.02  # the same start: world 1's friction alone moves it (measured 0.054 rad/s)
