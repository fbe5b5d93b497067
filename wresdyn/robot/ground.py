"""The robot on the ground: the contact settings both simulators use, the collision geometry, the floating-base
state and a standing start.

A floating-base robot stands on a floor in two simulators that must see the same contact: Newton
(``Robot.build_model(ground=True)`` stepped by ``SolverMuJoCo``, :mod:`wresdyn.sim.solvers`) and the MuJoCo C "real
robot" (``build_mujoco(ground=True)``, :class:`wresdyn.data.real_robot.RealRobot`). Newton's ``SolverMuJoCo``
turns every Newton shape into a MuJoCo geom (friction from ``shape_material_mu`` / ``mu_torsional`` /
``mu_rolling``, ``solref`` from ``shape_material_ke`` / ``kd``, ``gap`` as it is, ``margin`` zeroed where there
are boxes, MuJoCo's default ``solimp`` and ``condim``) and takes the solver options from its constructor;
:class:`~wresdyn.robot.contact.ContactSettings` states those numbers once, both sides are written from it, and
``tests/robot/test_standing.py`` checks the two compiled MuJoCo models field by field.

Conventions (Newton's, for both simulators): the base pose is the free root joint's ``joint_q``,
``[x y z qx qy qz qw]`` (position [m], unit quaternion scalar last); the base twist is its ``joint_qd``,
``[vx vy vz wx wy wz]``: the velocity of the base body's centre of mass [m/s] and its angular velocity [rad/s],
both in world axes. They are the base body's pose and twist in the world because the importers put the free
joint's frames at the base body's origin (checked by :func:`check_floating`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .contact import ContactSettings
from .description import Robot, RobotError

__all__ = ["CollisionShape", "ContactSettings", "FloatingState", "base_index", "check_floating", "collision_shapes",
           "standing_state"]


class CollisionShape(NamedTuple):
    """One collision shape of the robot, as Newton imported it."""

    index: int
    """Shape index in the robot's single-world builder."""
    label: str
    """Shape label (e.g. the USD prim path)."""
    body: int
    """Body the shape is attached to."""
    kind: str
    """``"box"``, ``"sphere"``, ``"capsule"``, ``"cylinder"`` or ``"ellipsoid"``."""
    size: np.ndarray
    """Newton's ``shape_scale``, shape (3,) [m]: box half extents; sphere radius; capsule / cylinder radius and
    half height along the shape's z axis; ellipsoid semi-axes."""
    transform: np.ndarray
    """Pose in the body frame, [x y z qx qy qz qw] [m], shape (7,)."""


_KINDS = ("box", "sphere", "capsule", "cylinder", "ellipsoid")


def collision_shapes(robot: Robot) -> list[CollisionShape]:
    """The robot's collision shapes (sites and visual-only shapes left out), in shape order.

    Raises:
        RobotError: a collision shape is not a primitive (a mesh, a cone, a height field): the MuJoCo model and
            the standing start are built from primitives only.
    """
    import newton

    b = robot.builder
    out = []
    for s in range(b.shape_count):
        flags = int(b.shape_flags[s])
        if flags & int(newton.ShapeFlags.SITE) or not flags & int(newton.ShapeFlags.COLLIDE_SHAPES):
            continue
        kind = newton.GeoType(int(b.shape_type[s])).name.lower()
        if kind not in _KINDS:
            raise RobotError(f"{robot.source}: collision shape {b.shape_label[s]!r} is a {kind}; standing on the "
                             f"ground needs primitive collision shapes ({', '.join(_KINDS)})")
        out.append(CollisionShape(s, str(b.shape_label[s]), int(b.shape_body[s]), kind,
                                  np.asarray(b.shape_scale[s], dtype=np.float64),
                                  np.asarray(b.shape_transform[s], dtype=np.float64)))
    return out


@dataclass(frozen=True)
class FloatingState:
    """The full state of one floating-base robot (Newton's free-joint convention, see the module docstring)."""

    base_pose: np.ndarray
    """Base body pose in the world, [x y z qx qy qz qw] ([m], unit quaternion), shape (7,)."""
    base_twist: np.ndarray
    """Base centre-of-mass velocity [m/s] and angular velocity [rad/s], world axes, shape (6,)."""
    q: np.ndarray
    """Actuated joint positions [rad or m], shape (n_dof,)."""
    qd: np.ndarray
    """Actuated joint velocities [rad/s or m/s], shape (n_dof,)."""


def check_floating(robot: Robot) -> None:
    """Raise :class:`RobotError` unless ``robot`` has a free root joint whose frames are the base body's origin
    (what every importer writes), so that the free joint's coordinates are the base pose in the world."""
    if robot.base != "floating":
        raise RobotError(f"{robot.source}: needs a floating base (load_robot(..., base='floating'))")
    identity = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    if not (np.allclose(robot.joint_X_p[0], identity) and np.allclose(robot.joint_X_c[0], identity)):
        raise RobotError(f"{robot.source}: the free root joint's frames are not the base body's origin")


def base_index(robot: Robot) -> tuple[int, int]:
    """Where the free root joint's 7 coordinates and 6 DoFs start in a world's ``joint_q`` and ``joint_qd``."""
    check_floating(robot)
    b = robot.builder
    root = list(b.joint_child).index(0)
    return int(b.joint_q_start[root]), int(b.joint_qd_start[root])


def _lowest(shape: CollisionShape, body_pose: np.ndarray, up: np.ndarray) -> float:
    """Lowest point of ``shape`` along ``up`` [m], the body at ``body_pose`` [x y z qx qy qz qw] in the world."""
    from scipy.spatial.transform import Rotation as R

    rb = R.from_quat(body_pose[3:])
    centre = body_pose[:3] + rb.apply(shape.transform[:3])
    axes = (rb * R.from_quat(shape.transform[3:])).as_matrix()  # columns: the shape's axes in the world
    u = up @ axes  # the up direction in the shape's axes
    s = shape.size
    depth = {
        "box": np.abs(u) @ s,
        "sphere": s[0],
        "capsule": abs(u[2]) * s[1] + s[0],
        "cylinder": abs(u[2]) * s[1] + s[0] * np.sqrt(max(0.0, 1.0 - u[2] ** 2)),
        "ellipsoid": np.linalg.norm(u * s),
    }[shape.kind]
    return float(up @ centre - depth)


def standing_state(robot: Robot, q: np.ndarray | None = None, height: float = 0.0) -> FloatingState:
    """The standing start: the base upright above the origin, joints at ``q``, at rest, and the lowest point of the
    robot's collision geometry ``height`` [m] above a floor through the origin (0: touching it).

    The geometry's height comes from Newton's forward kinematics (``newton.eval_fk``) over
    :func:`collision_shapes`.

    Args:
        robot: A floating-base robot (:func:`check_floating`).
        q: Joint positions [rad or m], shape (n_dof,); default the neutral pose ``robot.q0``.
        height: Clearance of the lowest point above the floor [m].
    """
    import newton

    check_floating(robot)
    q = robot.q0 if q is None else np.asarray(q, dtype=np.float64)
    if q.shape != (robot.n_dof,):
        raise ValueError(f"q has shape {q.shape}, the robot {robot.n_dof} joints")
    shapes = collision_shapes(robot)
    if not shapes:
        raise RobotError(f"{robot.source}: no collision shapes to stand on")
    model = robot.build_model(1, "cpu")
    state = model.state()
    joint_q = model.joint_q.numpy()
    start = base_index(robot)[0]
    joint_q[start:start + 7] = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
    joint_q[robot.q_index] = q
    state.joint_q.assign(joint_q)
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    body_q = state.body_q.numpy().astype(np.float64)
    up = -np.asarray(robot.gravity, dtype=np.float64) / np.linalg.norm(robot.gravity)
    lowest = min(_lowest(s, body_q[s.body], up) for s in shapes)
    pose = np.array([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    pose[:3] = (height - lowest) * up
    return FloatingState(pose, np.zeros(6), q.copy(), np.zeros(robot.n_dof))
