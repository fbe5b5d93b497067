"""The floor solver's constraint budget on mujoco_warp (Warp's CPU device): the floating humanoid with a dry
friction on every dof, its joints past their limits and its links in the floor, stepped by the solver wresdyn builds
for the floor, uses more rows than mujoco_warp's own sizing of the model as built gives it, and none past its
budget."""

from __future__ import annotations

import mujoco_warp as mjw
import newton
import numpy as np
import pytest

from wresdyn.sim.floor_budget import collision_geoms_mujoco, collision_shapes_newton, floor_budget
from wresdyn.sim.solvers import floor_solver

WORLDS = 3
STEPS = 3
DT = 0.002
"""Physics step [s] (the floor plants' 500 Hz)."""
SINK = 0.08
"""How deep each world's lowest box corner starts in the floor [m]."""


def test_budget_rule():
    assert floor_budget(22, 27) == (88, 4 * 88 + 54)
    assert floor_budget(0, 6) == (0, 12)
    with pytest.raises(ValueError):
        floor_budget(-1, 6)


@pytest.fixture(scope="module")
def floor_model(floating):
    return floating.build_model(WORLDS, "cpu", ground=True)


def test_newton_and_mujoco_count_the_same_collision_geoms(floor_model):
    solver = floor_solver(floor_model)
    n = collision_shapes_newton(floor_model)
    assert n == collision_geoms_mujoco(solver.mj_model) > 0
    assert (solver.mjw_data.njmax, solver.mjw_data.naconmax) == (
        floor_budget(n, solver.mj_model.nv)[1], WORLDS * floor_budget(n, solver.mj_model.nv)[0])


def _lowest_corners(solver) -> np.ndarray:
    """Height of each world's lowest robot box corner [m] (worlds,), from mujoco_warp's geom poses."""
    robot = solver.mj_model.geom_bodyid != 0  # (ngeom,)
    pos = solver.mjw_data.geom_xpos.numpy()[:, robot]  # (worlds, boxes, 3) [m]
    rot = solver.mjw_data.geom_xmat.numpy()[:, robot]  # (worlds, boxes, 3, 3)
    half = solver.mj_model.geom_size[robot]  # (boxes, 3) half-extents [m]
    return np.min(pos[..., 2] - np.sum(np.abs(rot[..., 2, :]) * half, -1), -1)


def _step(solver, model, q: np.ndarray, steps: int) -> tuple[np.ndarray, int]:
    """Step every world ``steps`` times from joint coordinates ``q`` (worlds, nq) at rest; the most constraint rows
    each world asked for (worlds,) (mujoco_warp counts past ``njmax`` too) and the union of the overflow flags."""
    state, out, control = model.state(), model.state(), model.control()
    state.joint_q.assign(q.ravel())
    rows, over = [], 0
    for _ in range(steps):
        solver.step(state, out, control, None, DT)
        state, out = out, state
        rows.append(solver.mjw_data.nefc.numpy())
        over |= int(np.bitwise_or.reduce(solver.mjw_data.overflow.numpy()))
    return np.max(rows, axis=0), over


def test_no_constraint_overflow_with_friction_limits_and_contacts(floor_model):
    """World 0 upright, world 1 on its back, world 2 on its side, each with its lowest box corner 8 cm in the floor
    (several links on the floor at once, none on more than 4 corners: a box sunk past its own thickness makes up to
    8 in mujoco_warp, a state the budget does not cover); every joint 0.05 rad past its lower limit; a dry friction
    on every dof (as a randomised draw turns on after construction)."""
    model = floor_model
    solver = floor_solver(model)
    nv, nq = solver.mj_model.nv, model.joint_coord_count // WORLDS
    model.joint_friction.assign(np.full(model.joint_dof_count, 0.5, dtype=np.float32))
    solver.notify_model_changed(newton.ModelFlags.JOINT_DOF_PROPERTIES)
    q = model.joint_q.numpy().reshape(WORLDS, nq)  # (worlds, 7 + joints): base [x y z qx qy qz qw], joints
    lower = model.joint_limit_lower.numpy().reshape(WORLDS, nv)[:, 6:]  # (worlds, joints) [rad]
    q[:, 7:] = lower - 0.05
    q[1, 3:7] = [0.0, np.sqrt(0.5), 0.0, np.sqrt(0.5)]  # 90 degrees about y
    q[2, 3:7] = [np.sqrt(0.5), 0.0, 0.0, np.sqrt(0.5)]  # 90 degrees about x
    q[:, 2] = 1.5  # clear of the floor: place each world from its own lowest corner
    _step(solver, model, q, 1)
    q[:, 2] -= _lowest_corners(solver) + SINK
    rows, over = _step(solver, model, q, STEPS)
    d = solver.mjw_data
    n = int(d.nacon.numpy()[0])
    per_geom = np.unique(np.stack([d.contact.worldid.numpy()[:n], d.contact.geom.numpy()[:n, 1]]), axis=1,
                         return_counts=True)[1]  # contacts of each (world, box) pair in contact
    njmax = d.njmax
    assert njmax == floor_budget(collision_shapes_newton(model), nv)[1]
    assert per_geom.max() <= 4
    assert not over & (mjw.OverflowType.NEFC | mjw.OverflowType.NARROWPHASE), f"overflow flags {over:#x}"
    assert rows.max() <= njmax
    # the scenario asks for what the budget exists for: more rows than mujoco_warp's sizing of the model as built
    # gave (64: no friction loss, no limit active, a few contacts)
    assert rows.max() > 64, rows
