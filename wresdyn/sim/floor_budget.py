"""How many contacts and constraint rows mujoco_warp allocates per world for a robot on the floor: one rule for
wresdyn's floor solver (:func:`wresdyn.sim.solvers.make_solver` with a ground) and the oracle's plant
(:class:`wresdyn.skills.real_warp.RealWarpPlant`).

mujoco_warp allocates its constraint rows per world once, at construction (``njmax``), and drops the rows past
it in a world that needs more (it flags ``OverflowType.NEFC`` in ``data.overflow`` and prints "nefc overflow"): that
world's step then misses constraints. Left to itself, it sizes ``njmax`` from the model as built (53 rows, rounded
up to 64, for the floating humanoid), but the rows a world needs depend on its state and on the physics drawn for
it after construction:

- each contact with the floor: 4 rows (pyramidal friction cone at ``condim`` 3, ``2 (condim - 1)``; an elliptic
  cone at ``condim`` 3 needs 3);
- each dof with a friction loss: 1 row (the model as built has none; a randomised or identified dry friction
  turns them on, through ``notify_model_changed``, on any dof);
- each limited joint past a limit: 1 row.

The rule sizes for the worst of each: every collision geom of the robot touching the floor at
:data:`CONTACTS_PER_GEOM` points, a friction loss on every dof and a limit row on every dof (an upper bound on
the limited joints).
"""

from __future__ import annotations

import numpy as np

__all__ = ["CONTACTS_PER_GEOM", "ROWS_PER_CONTACT", "floor_budget", "collision_geoms_mujoco",
           "collision_shapes_newton"]

CONTACTS_PER_GEOM = 4
"""Contacts a box touching the floor plane makes at most (MuJoCo's box-plane collision keeps 4 corners): what the
rule allocates per collision geom, so a robot of boxes lying on the floor with every link down still fits (a robot
of other collision shapes may need more: mujoco_warp then flags the world's ``data.overflow``)."""

ROWS_PER_CONTACT = 4
"""Constraint rows of one contact: the pyramidal friction cone at ``condim`` 3 (``2 (condim - 1)`` edges; wresdyn's
floor contact, :class:`~wresdyn.robot.contact.ContactSettings`), an upper bound for the elliptic cone's 3."""


def floor_budget(n_collide: int, nv: int) -> tuple[int, int]:
    """``(nconmax, njmax)`` per world for a robot of ``n_collide`` collision geoms (one world's, the floor not
    counted) and ``nv`` dofs (the free joint's 6 included): ``nconmax = 4 n_collide`` contacts and
    ``njmax = 4 nconmax + nv + nv`` constraint rows (contacts, friction loss on every dof, a limit on every dof)."""
    if n_collide < 0 or nv < 0:
        raise ValueError(f"collision geoms ({n_collide}) and dofs ({nv}) must be >= 0")
    nconmax = CONTACTS_PER_GEOM * int(n_collide)
    return nconmax, ROWS_PER_CONTACT * nconmax + 2 * int(nv)


def collision_geoms_mujoco(mj_model) -> int:
    """Collision geoms of a one-world MuJoCo model (``contype`` or ``conaffinity`` set) on a moving body: the
    robot's, the floor and anything else fixed to the world body not counted."""
    collide = (np.asarray(mj_model.geom_contype) | np.asarray(mj_model.geom_conaffinity)) > 0
    return int(np.sum(collide & (np.asarray(mj_model.geom_bodyid) != 0)))


def collision_shapes_newton(model) -> int:
    """Collision shapes (``ShapeFlags.COLLIDE_SHAPES``) of the busiest world of a Newton model: the robot's
    shapes of one world; the shared ones (``shape_world`` -1: the floor) not counted."""
    from newton import ShapeFlags

    collide = (model.shape_flags.numpy() & int(ShapeFlags.COLLIDE_SHAPES)) != 0  # (shape_count,)
    world = model.shape_world.numpy()  # (shape_count,) world index, -1 shared by all
    mine = world[collide & (world >= 0)]
    return int(np.bincount(mine).max()) if mine.size else 0
