"""The robot tree that :class:`~wresdyn.sim.solver_replay.SolverReplay` compiles: constants read once from a Newton model.

A replay model holds ``W`` copies of one fixed-base robot, one per world. This module reads world 0's
articulation out of the :class:`newton.Model` arrays, checks that every world holds the same robot, and
reduces it to what the generated kernel needs: for each 1-DoF joint (revolute or prismatic) its parent
DoF, the constant transforms around the joint and the axis, and for each body the DoF whose rigid group
it belongs to with its constant pose in that DoF's body frame. Bodies welded by fixed joints join the
group of the moving body they hang from, so the kernel only sees DoFs. Masses, centres of mass and
inertias are not constants, nor are the per-DoF drive and limit parameters: the kernel reads them from
the model arrays every launch, so they may differ between worlds and change without recompiling.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from ...errors import WresdynError

__all__ = ["ReplayTree", "TreeError", "tree_from_model"]

_SNAP = 1e-12
"""Constants closer than this to 0 or +-1 are snapped, so the generator can fold them away."""


class TreeError(WresdynError):
    """The Newton model is not a set of identical fixed-base revolute/prismatic trees."""


@dataclass(frozen=True)
class ReplayTree:
    """One world's robot, reduced to its degrees of freedom. Positions are relative to ``origin``."""

    n_dof: int
    """Number of 1-DoF joints."""
    prismatic: np.ndarray
    """True for a prismatic DoF, shape (n_dof,)."""
    parent: np.ndarray
    """Parent DoF (the nearest moving ancestor), -1 when the DoF hangs from the fixed base, shape (n_dof,)."""
    rot_pj: np.ndarray
    """Joint frame orientation in the parent DoF's body frame (world frame if parent is -1), shape (n_dof, 3, 3)."""
    pos_pj: np.ndarray
    """Joint frame origin in the parent DoF's body frame (world frame, relative to ``origin``) [m], shape (n_dof, 3)."""
    rot_jc: np.ndarray
    """Child body frame orientation in the joint frame, inv(X_c), shape (n_dof, 3, 3)."""
    pos_jc: np.ndarray
    """Child body frame origin in the joint frame [m], shape (n_dof, 3)."""
    axis: np.ndarray
    """Joint axis in the joint frame (unit), shape (n_dof, 3)."""
    body_dof: np.ndarray
    """DoF whose rigid group each body of one world belongs to (the DoF moving it, or the one its welded
    ancestor hangs from), -1 for bodies fixed to the base, shape (bodies_per_world,)."""
    rot_db: np.ndarray
    """Body frame orientation in its DoF's body frame (identity unless welded), shape (bodies_per_world, 3, 3)."""
    pos_db: np.ndarray
    """Body frame origin in its DoF's body frame [m], shape (bodies_per_world, 3)."""
    origin: np.ndarray
    """World position of the fixed base [m], shape (3,); kernel positions are relative to it (float32 precision)."""
    q_offset: np.ndarray
    """Index of each DoF in one world's slice of ``joint_q``, shape (n_dof,)."""
    qd_offset: np.ndarray
    """Index of each DoF in one world's slice of ``joint_qd`` / ``joint_f`` / targets, shape (n_dof,)."""
    coords_per_world: int
    """Length of one world's slice of ``joint_q``."""
    dofs_per_world: int
    """Length of one world's slice of ``joint_qd``."""
    bodies_per_world: int
    """Length of one world's slice of ``body_mass`` / ``body_com`` / ``body_inertia``."""
    world_count: int
    """Number of worlds."""

    def ancestors(self, k: int) -> list[int]:
        """DoFs on the path from ``k``'s parent to the base, nearest first."""
        out = []
        j = int(self.parent[k])
        while j >= 0:
            out.append(j)
            j = int(self.parent[j])
        return out

    def group(self, k: int) -> list[int]:
        """Bodies (index within a world) of DoF ``k``'s rigid group."""
        return [int(b) for b in np.flatnonzero(self.body_dof == k)]

    def branches(self) -> list[list[int]]:
        """The DoFs of each subtree hanging from the fixed base, in DoF order: the base does not move, so these
        subtrees share no inertia, no mass-matrix entry and no friction coupling, and step independently."""
        top = [k if self.parent[k] < 0 else -1 for k in range(self.n_dof)]
        for k in range(self.n_dof):  # parents come first in DoF order
            if top[k] < 0:
                top[k] = top[int(self.parent[k])]
        return [[k for k in range(self.n_dof) if top[k] == r] for r in sorted(set(top))]

    def restrict(self, dofs: list[int]) -> "ReplayTree":
        """The robot with only ``dofs`` (a union of :meth:`branches`) moving, at their offsets in a world's slices:
        the bodies of the other DoFs count as fixed to the base, which they are not, so only a whole branch gives
        that branch's motion."""
        dofs = [int(k) for k in dofs]
        new = {k: i for i, k in enumerate(dofs)}
        if any(int(self.parent[k]) >= 0 and int(self.parent[k]) not in new for k in dofs):
            raise TreeError("restrict needs whole subtrees of the base")
        return ReplayTree(
            n_dof=len(dofs), prismatic=self.prismatic[dofs],
            parent=np.array([new.get(int(self.parent[k]), -1) for k in dofs], dtype=np.int64),
            rot_pj=self.rot_pj[dofs], pos_pj=self.pos_pj[dofs], rot_jc=self.rot_jc[dofs], pos_jc=self.pos_jc[dofs],
            axis=self.axis[dofs], body_dof=np.array([new.get(int(k), -1) for k in self.body_dof], dtype=np.int64),
            rot_db=self.rot_db, pos_db=self.pos_db, origin=self.origin, q_offset=self.q_offset[dofs],
            qd_offset=self.qd_offset[dofs], coords_per_world=self.coords_per_world,
            dofs_per_world=self.dofs_per_world, bodies_per_world=self.bodies_per_world, world_count=self.world_count,
        )

    def digest(self) -> str:
        """Hash of the constants the kernel bakes in: topology and joint frames, not the inertial parameters
        (read from the model arrays) nor the world count."""
        h = hashlib.sha256()
        for a in (self.prismatic, self.parent, self.rot_pj, self.pos_pj, self.rot_jc, self.pos_jc, self.axis,
                  self.body_dof, self.rot_db, self.pos_db, self.q_offset, self.qd_offset):
            h.update(np.ascontiguousarray(a).tobytes())
        h.update(f"{self.coords_per_world},{self.dofs_per_world},{self.bodies_per_world}".encode())
        return h.hexdigest()[:16]


def _quat_to_mat(q: np.ndarray) -> np.ndarray:
    x, y, z, w = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def _tf(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """[p, q_xyzw] -> (R, p)."""
    return _quat_to_mat(np.asarray(x[3:7], dtype=np.float64)), np.asarray(x[:3], dtype=np.float64)


def _mul(a, b):
    return a[0] @ b[0], a[0] @ b[1] + a[1]


def _inv(a):
    return a[0].T, -a[0].T @ a[1]


def _snap(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a[np.abs(a) < _SNAP] = 0.0
    a[np.abs(a - 1.0) < _SNAP] = 1.0
    a[np.abs(a + 1.0) < _SNAP] = -1.0
    return a


def tree_from_model(model) -> ReplayTree:
    """Read the robot of world 0 from ``model`` and check that all worlds hold the same one.

    Raises:
        TreeError: the model has a floating base, unsupported joints, or worlds that differ.
    """
    import newton

    JT = newton.JointType
    w_count = int(model.world_count)
    n_j, n_b = int(model.joint_count), int(model.body_count)
    if w_count < 1 or n_j == 0 or n_j % w_count or n_b % w_count:
        raise TreeError(f"SolverReplay needs one identical robot per world; got {n_j} joints, {n_b} bodies in "
                        f"{w_count} worlds")
    jpw, bpw = n_j // w_count, n_b // w_count
    nq, nd = int(model.joint_coord_count), int(model.joint_dof_count)
    if nq % w_count or nd % w_count:
        raise TreeError("joint coordinates are not split evenly between worlds")
    cpw, dpw = nq // w_count, nd // w_count

    jt = model.joint_type.numpy().reshape(w_count, jpw)
    jpar = model.joint_parent.numpy().reshape(w_count, jpw)
    jch = model.joint_child.numpy().reshape(w_count, jpw)
    qs = model.joint_q_start.numpy()[:n_j].reshape(w_count, jpw)
    ds = model.joint_qd_start.numpy()[:n_j].reshape(w_count, jpw)
    xp = model.joint_X_p.numpy().reshape(w_count, jpw, 7)
    xc = model.joint_X_c.numpy().reshape(w_count, jpw, 7)
    axis = model.joint_axis.numpy().reshape(w_count, dpw, 3)

    # every world the same robot: topology and joint frames (the root's position may be shifted)
    boff = (np.arange(w_count) * bpw)[:, None]
    same = (
        (jt == jt[0]).all()
        and (np.where(jpar >= 0, jpar - boff, -1) == jpar[0]).all()
        and (jch - boff == jch[0]).all()
        and (qs - (np.arange(w_count) * cpw)[:, None] == qs[0]).all()
        and (ds - (np.arange(w_count) * dpw)[:, None] == ds[0]).all()
        and np.allclose(xp[:, :, 3:], xp[0, :, 3:]) and np.allclose(xc, xc[0])
        and np.allclose(np.where((jpar >= 0)[..., None], xp[..., :3], 0.0),
                        np.where((jpar[0] >= 0)[:, None], xp[0, :, :3], 0.0))
        and np.allclose(axis, axis[0])
    )
    if not same:
        raise TreeError("SolverReplay needs the same robot in every world (topology and joint frames); "
                        "per-world inertias, gains, limits, armature and friction may differ")

    jt, jpar, jch, qs, ds, xp, xc = jt[0], jpar[0], jch[0], qs[0], ds[0], xp[0], xc[0]
    roots = np.flatnonzero(jpar < 0)
    if len(roots) != 1:
        raise TreeError(f"SolverReplay needs one articulation per world, found {len(roots)} roots")
    r = int(roots[0])
    if jt[r] == JT.FREE:
        raise TreeError("SolverReplay supports fixed-base robots only (the root joint is FREE); use SolverFeatherstone")
    if jt[r] != JT.FIXED:
        raise TreeError(f"SolverReplay needs a FIXED root joint, got {JT(int(jt[r])).name}")
    for j in range(jpw):
        if jt[j] not in (JT.REVOLUTE, JT.PRISMATIC, JT.FIXED):
            raise TreeError(f"SolverReplay supports revolute, prismatic and fixed joints, not {JT(int(jt[j])).name}")

    # body -> (anchor DoF or -1, body frame in the anchor frame); process joints parents first
    root_pose = _mul(_tf(xp[r]), _inv(_tf(xc[r])))
    origin = root_pose[1].copy()
    anchor = {int(jch[r]): (-1, (root_pose[0], root_pose[1] - origin))}
    order, pending = [r], [j for j in range(jpw) if j != r]
    while pending:
        ready = [j for j in pending if int(jpar[j]) in anchor]
        if not ready:
            raise TreeError("joints do not form a tree rooted at the base")
        for j in list(pending):  # index order, so a parents-first model keeps Newton's DoF order
            if int(jpar[j]) not in anchor:
                continue
            p = int(jpar[j])
            a, x_ap = anchor[p]
            x_aj = _mul(x_ap, _tf(xp[j]))
            if jt[j] == JT.FIXED:
                anchor[int(jch[j])] = (a, _mul(x_aj, _inv(_tf(xc[j]))))
            else:
                order.append(j)
                anchor[int(jch[j])] = (len(order) - 2, (np.eye(3), np.zeros(3)))
            pending.remove(j)
    dofs = order[1:]
    n = len(dofs)
    if n == 0:
        raise TreeError("the robot has no revolute or prismatic joint")
    parent = np.full(n, -1, dtype=np.int64)
    rot_pj, pos_pj, rot_jc, pos_jc, ax = (np.zeros((n, 3, 3)), np.zeros((n, 3)), np.zeros((n, 3, 3)),
                                           np.zeros((n, 3)), np.zeros((n, 3)))
    for k, j in enumerate(dofs):
        a, x_ap = anchor[int(jpar[j])]
        parent[k] = a
        rot_pj[k], pos_pj[k] = _mul(x_ap, _tf(xp[j]))
        rot_jc[k], pos_jc[k] = _inv(_tf(xc[j]))
        axv = axis[0, ds[j]].astype(np.float64)
        ax[k] = axv / np.linalg.norm(axv)

    body_dof = np.full(bpw, -1, dtype=np.int64)
    rot_db, pos_db = np.tile(np.eye(3), (bpw, 1, 1)), np.zeros((bpw, 3))
    for b in range(bpw):
        a, (rab, pab) = anchor.get(b, (-1, (None, None)))  # a body no joint reaches does not move
        if a >= 0:
            body_dof[b], rot_db[b], pos_db[b] = a, rab, pab

    return ReplayTree(
        n_dof=n,
        prismatic=np.array([jt[j] == JT.PRISMATIC for j in dofs]),
        parent=parent,
        rot_pj=_snap(rot_pj), pos_pj=_snap(pos_pj), rot_jc=_snap(rot_jc), pos_jc=_snap(pos_jc), axis=_snap(ax),
        body_dof=body_dof, rot_db=_snap(rot_db), pos_db=_snap(pos_db), origin=origin,
        q_offset=np.array([qs[j] for j in dofs], dtype=np.int64),
        qd_offset=np.array([ds[j] for j in dofs], dtype=np.int64),
        coords_per_world=cpw, dofs_per_world=dpw, bodies_per_world=bpw, world_count=w_count,
    )
