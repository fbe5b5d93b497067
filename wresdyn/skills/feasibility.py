"""Whether a floor motion can be played at all, from the reference alone (Pinocchio's rigid-body dynamics, no
controller): where the floor must push, and the joint torques the planted soles leave to the drives.

Zero-moment point. With the whole robot's mass m, centre of mass c and the rates of its linear momentum ḣ and of its
angular momentum about c, L̇_c, the floor must supply the force f = ḣ − m g and, about the world origin, the moment
n = c × f + L̇_c. The point of the floor (z = 0) about which that moment has no horizontal part is

    p = (−n_y / f_z, n_x / f_z),

and flat soles can only push inside the convex hull of their footprints: where p leaves the hull of the soles the
reference plants, no robot of these masses plays the motion with those soles flat (the floor would have to pull).

Joint torques. The floating-base dynamics with the planted soles' contact wrenches λ (6 per sole, in the sole's
frame),

    M(q) v̇ + h(q, v) = Sᵀ τ + J_cᵀ λ,

fix λ through their six base rows on one sole; on two, λ is the split that minimises Σ_j (τ_j / τ_max,j)² under
those rows (the drives' share of the load as even as the limits allow). The drives must also overcome the joints'
dry friction and damping: τ + friction · sign(q̇) + damping · q̇.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot.ground import collision_shapes
from ..robot.pinocchio_model import build_pinocchio

__all__ = ["FloorFeasibility", "floor_feasibility", "screen", "FOOT_BODIES", "SOLE_FRAMES", "SCREEN_EVERY_S",
           "SCREEN_SKIP_S"]

FOOT_BODIES = ("left_foot", "right_foot")
"""The foot bodies (left, right): the soles' collision boxes here, the bodies whose slip the tracking environment
penalises where the reference plants them (:mod:`.env`). Kept here, torch-free, so that the processes that draw the
floor motions import no torch."""
SOLE_FRAMES = ("left_sole", "right_sole")
"""The sole frames the contact wrenches act at (left, right), in :data:`FOOT_BODIES` order."""

SCREEN_EVERY_S = 0.01
"""Sample spacing [s] of :func:`screen` (the zero-moment point of a minimum-jerk reference changes over tenths of a
second)."""
SCREEN_SKIP_S = 0.01
"""Time [s] :func:`screen` leaves out around each change of the planted soles (the base step of the reference there,
see ``skip``), and at least two samples: the central differences of the velocity and of the acceleration spread the
step over two samples either side."""


@dataclass
class FloorFeasibility:
    """The dynamics a floor motion asks for, at the samples ``index`` of the motion."""

    index: np.ndarray
    """Motion samples analysed, shape (T',)."""
    zmp: np.ndarray
    """Zero-moment point on the floor [m], shape (T', 2)."""
    margin: np.ndarray
    """Distance of the zero-moment point inside the planted soles' support polygon [m] (negative: outside),
    shape (T',)."""
    tau: np.ndarray
    """Joint torques the motion needs [N*m], shape (T', n_dof)."""
    planted: np.ndarray
    """Planted soles (left, right), bool, shape (T', 2)."""


def _foot_boxes(robot) -> list[np.ndarray]:
    """The corners of each foot's collision boxes in the foot's frame [m], (8 k, 3) per foot of
    :data:`FOOT_BODIES`."""
    from scipy.spatial.transform import Rotation as R

    shapes = collision_shapes(robot)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)], dtype=np.float64)
    out = []
    for foot in FOOT_BODIES:
        body = list(robot.body_names).index(foot)
        boxes = [R.from_quat(s.transform[3:]).apply(signs * s.size) + s.transform[:3]
                 for s in shapes if s.body == body and s.kind == "box"]
        if not boxes:
            raise ValueError(f"{robot.source}: body {foot!r} has no collision box to stand on")
        out.append(np.concatenate(boxes))
    return out


def _margin(points: np.ndarray, p: np.ndarray) -> float:
    """Signed distance of ``p`` inside the convex hull of ``points`` (2-D) [m]."""
    from scipy.spatial import ConvexHull

    hull = ConvexHull(points)
    return float(-(hull.equations[:, :2] @ p + hull.equations[:, 2]).max())


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross`` of two 3-vectors, the same products and differences without its axis handling (the screening's
    loop calls it once a sample)."""
    a0, a1, a2 = a
    b0, b1, b2 = b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def floor_feasibility(robot, motion, rate_hz: float, effort: np.ndarray | None = None,
                      friction: np.ndarray | None = None, damping: np.ndarray | None = None, every: int = 1,
                      skip: float = 0.0, model=None) -> FloorFeasibility:
    """Zero-moment point, its margin in the support polygon and the joint torques of ``motion`` (a
    :class:`~wresdyn.skills.motions.Motion` on the floor) on ``robot`` (a floating base; its masses and inertias are the
    ones used).

    Args:
        rate_hz: The motion's sample rate [Hz].
        effort: The limits [N*m] (n_dof,) that weigh the torque split of double support (default ``robot.effort``).
        friction, damping: The joints' dry friction [N*m] and viscous damping [N*m*s/rad] the drives overcome
            (default the robot's).
        every: Analyse every this many samples.
        skip: Leave out the samples within this time [s] of a change of the planted soles (default none): the
            reference's base can step there by the planted soles' average, which finite differences turn into a
            spike of acceleration.
        model: ``robot``'s Pinocchio model (:func:`~wresdyn.robot.pinocchio_model.build_pinocchio`), where the caller
            keeps one for many motions (default: built here).
    """
    import pinocchio as pin

    if robot.base != "floating":
        raise ValueError(f"{robot.source}: the feasibility of a floor motion needs the robot with a free base")
    effort = np.asarray(robot.effort if effort is None else effort, dtype=np.float64)
    friction = np.asarray(robot.friction if friction is None else friction, dtype=np.float64)
    damping = np.asarray(robot.damping if damping is None else damping, dtype=np.float64)
    model = build_pinocchio(robot) if model is None else model
    data = model.createData()
    soles = [model.getFrameId(s) for s in SOLE_FRAMES]
    feet = [model.getFrameId(b) for b in FOOT_BODIES]
    boxes = _foot_boxes(robot)
    mass = pin.computeTotalMass(model)
    g = np.asarray(robot.gravity, dtype=np.float64)
    dt = 1.0 / float(rate_hz)
    cfg = np.concatenate([motion.base, motion.q], axis=1)
    n_t = len(cfg)
    vel = np.zeros((n_t, model.nv))
    for k in range(1, n_t - 1):
        vel[k] = pin.difference(model, cfg[k - 1], cfg[k + 1]) / (2.0 * dt)
    acc = np.gradient(vel, dt, axis=0)
    change = np.flatnonzero((motion.planted[1:] != motion.planted[:-1]).any(-1)) + 1
    near = np.zeros(n_t, dtype=bool)
    for k in change:
        near[max(0, k - int(round(skip / dt))):k + int(round(skip / dt)) + 1] = skip > 0
    index = np.array([k for k in range(2, n_t - 2, every) if not near[k]])
    weight = 1.0 / np.where(np.isfinite(effort) & (effort > 0), effort, 1e3)
    zmp, margin, tau = np.zeros((len(index), 2)), np.zeros(len(index)), np.zeros((len(index), robot.n_dof))
    for row, k in enumerate(index):
        q, v, a = cfg[k], vel[k], acc[k]
        rnea = pin.rnea(model, data, q, v, a)
        pin.computeJointJacobians(model, data, q)
        pin.framesForwardKinematics(model, data, q)
        pin.computeCentroidalMomentumTimeVariation(model, data, q, v, a)
        f = data.dhg.linear - mass * g
        n = _cross(data.com[0], f) + data.dhg.angular
        zmp[row] = (-n[1] / f[2], n[0] / f[2])
        down = [i for i in range(2) if motion.planted[k, i]]
        corners = []
        for i in down:
            place = data.oMf[feet[i]]
            corners.append((place.rotation @ boxes[i].T).T[:, :2] + place.translation[:2])
        margin[row] = _margin(np.concatenate(corners), zmp[row])
        jac = np.concatenate([pin.getFrameJacobian(model, data, soles[i], pin.LOCAL) for i in down])
        base_rows, joint_rows = jac[:, :6].T, jac[:, 6:].T
        if len(down) == 1:
            lam = np.linalg.solve(base_rows, rnea[:6])
        else:  # min Σ (w τ)² with τ = rnea_j − joint_rows λ, under base_rows λ = rnea_base
            lam0 = np.linalg.lstsq(base_rows, rnea[:6], rcond=None)[0]
            null = np.linalg.svd(base_rows)[2][6:].T
            z = np.linalg.lstsq(weight[:, None] * (joint_rows @ null),
                                weight * (rnea[6:] - joint_rows @ lam0), rcond=None)[0]
            lam = lam0 + null @ z
        qd = motion.qd[k]
        tau[row] = rnea[6:] - joint_rows @ lam + friction * np.sign(qd) + damping * qd
    return FloorFeasibility(index, zmp, margin, tau, motion.planted[index])



def screen(robot, motion, rate_hz: float, model=None) -> dict:
    """Whether flat soles can carry ``motion`` on ``robot`` (a floating base, its nominal masses and limits): the
    zero-moment point never leaves the planted soles and no joint torque passes its effort limit, sampled every
    :data:`SCREEN_EVERY_S`. Returns ``feasible``, ``zmp_margin_m`` (the smallest margin [m], negative: outside) and
    ``effort_ratio`` (the largest |τ| / τ_max); ``model``: as :func:`floor_feasibility`'s."""
    f = floor_feasibility(robot, motion, rate_hz, every=max(1, int(round(SCREEN_EVERY_S * rate_hz))),
                          skip=max(SCREEN_SKIP_S, 2.0 / rate_hz), model=model)
    effort = np.asarray(robot.effort, dtype=np.float64)
    limited = np.isfinite(effort) & (effort > 0)
    ratio = float((np.abs(f.tau[:, limited]) / effort[limited]).max())
    margin = float(f.margin.min())
    return {"feasible": bool(margin >= 0.0 and ratio <= 1.0), "zmp_margin_m": margin, "effort_ratio": ratio}
