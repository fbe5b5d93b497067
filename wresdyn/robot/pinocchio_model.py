"""The same robot as a Pinocchio model, built joint by joint from a :class:`~wresdyn.robot.description.Robot`.

Used for inverse kinematics (named sole frames) and for the rigid-body terms of the paper's eq. 1,
M(q) q̈ + C(q, q̇) q̇ + G(q) + f(q, q̇, q̈) = τ_pd + τ_res: ``pin.crba`` gives M (armature included on the
diagonal), ``pin.rnea(q, q̇, 0)`` gives C q̇ + G and ``pin.computeGeneralizedGravity`` gives G.

Each Pinocchio joint frame is the Newton joint frame (``joint_X_p`` in the parent body); bodies welded by
fixed joints are merged into their parent's Pinocchio joint, and every Newton body also becomes a
Pinocchio ``BODY`` frame of the same name, so forward kinematics can be compared body by body.
"""

from __future__ import annotations

import numpy as np

from .description import Robot

__all__ = ["build_pinocchio", "body_placement"]


def _se3(tf: np.ndarray):
    import pinocchio as pin
    from scipy.spatial.transform import Rotation as R

    return pin.SE3(R.from_quat(tf[3:]).as_matrix(), np.asarray(tf[:3], dtype=np.float64))


def build_pinocchio(robot: Robot):
    """Build a :class:`pinocchio.Model` of ``robot``.

    The configuration is ``robot.joint_names`` in order (``nq == nv == n_dof``) for a fixed base; a floating
    base prepends a free-flyer (``nq = 7 + n_dof``: position, quaternion [x y z w]; ``nv = 6 + n_dof``).
    """
    import pinocchio as pin

    model = pin.Model()
    model.name = robot.source.stem
    model.gravity = pin.Motion(np.asarray(robot.gravity, dtype=np.float64), np.zeros(3))
    dof_of_body = {int(b): i for i, b in enumerate(robot.dof_body)}
    # per body: (pinocchio joint id, placement of the body frame in that joint's frame)
    attach: list[tuple[int, object]] = []
    armature = []
    for b in range(robot.n_bodies):
        jt = robot.joint_type[b]
        if robot.body_parent[b] < 0:
            pj, parent_in_joint = 0, pin.SE3.Identity()
        else:
            pj, parent_in_joint = attach[robot.body_parent[b]]
        # joint frame in the parent Pinocchio joint's frame
        joint_in_pj = parent_in_joint * _se3(robot.joint_X_p[b])
        body_in_joint = _se3(robot.joint_X_c[b]).inverse()
        if jt == "fixed":
            jid, body_in_jid = pj, joint_in_pj * body_in_joint
        else:
            if jt == "free":
                jmodel = pin.JointModelFreeFlyer()
                name = robot.body_names[b] + "_free"
            else:
                i = dof_of_body[b]
                axis = np.asarray(robot.axis[i], dtype=np.float64)
                jmodel = pin.JointModelRevoluteUnaligned(axis) if jt == "revolute" else pin.JointModelPrismaticUnaligned(axis)
                name = robot.joint_names[i]
                armature.append(robot.armature[i])
            jid = model.addJoint(pj, jmodel, joint_in_pj, name)
            if jt == "free":
                armature = [0.0] * 6 + armature
            body_in_jid = body_in_joint
        inertia = pin.Inertia(float(robot.body_mass[b]), robot.body_com[b], 0.5 * (robot.body_inertia[b] + robot.body_inertia[b].T))
        model.appendBodyToJoint(jid, inertia.se3Action(body_in_jid), pin.SE3.Identity())
        attach.append((jid, body_in_jid))
        prev = model.getFrameId(model.names[jid]) if jid > 0 else 0
        model.addFrame(pin.Frame(robot.body_names[b], jid, prev, body_in_jid, pin.FrameType.BODY))
    for name, (b, tf) in robot.frames.items():
        jid, body_in_jid = attach[b]
        model.addFrame(pin.Frame(name, jid, model.getFrameId(robot.body_names[b]), body_in_jid * _se3(tf), pin.FrameType.OP_FRAME))
    model.armature = np.asarray(armature, dtype=np.float64)
    lower, upper = np.full(model.nq, -np.inf), np.full(model.nq, np.inf)
    start = 7 if robot.base == "floating" else 0
    lower[start:], upper[start:] = robot.lower, robot.upper
    model.lowerPositionLimit, model.upperPositionLimit = lower, upper
    model.effortLimit = np.concatenate([np.zeros(model.nv - robot.n_dof), np.where(np.isfinite(robot.effort), robot.effort, 1e9)])
    return model


def body_placement(model, data, name: str):
    """World placement (``pin.SE3``) of the frame ``name`` after ``pin.framesForwardKinematics``."""
    return data.oMf[model.getFrameId(name)]
