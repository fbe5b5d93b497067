"""Inverse kinematics of named frames (by default both soles) on a fixed base, with Pinocchio.

Each frame (a site or a body, by name; by default ``left_sole`` and ``right_sole``) is driven to a full 6-D
target (position and orientation), so a 6-DoF leg has a locally unique solution and no null-space drift. All
frames are solved together as one damped least-squares problem (Levenberg-Marquardt: the damping grows with
the squared error, so steps are Gauss-Newton near the solution and cautious far from it), every iterate is
clamped into the joint limits, and a path is solved sample by sample warm-started from the previous solution,
which keeps the command sequence smooth. Joints outside the frames' chains are not moved.

What the chains can track is checked up front. A frame whose chain (the joints between the base and it) cannot
move it along all six pose directions (fewer than 6 joints, or a Jacobian of lower rank) cannot follow a full
pose: then every frame is driven to a position only (3-D targets, ``position_only``; the orientation is whatever
the joints give). A chain of fewer than 3 joints, one that moves its frame's position along fewer than 3
directions, or two frames sharing a joint (their targets would fight) is refused with a one-line
:class:`RobotError`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot.description import Robot, RobotError
from ..robot.pinocchio_model import build_pinocchio

__all__ = ["FootIK", "IKConfig", "SOLES", "POSE_DOF", "MIN_CHAIN_DOF"]

SOLES = ("left_sole", "right_sole")
"""Default frames driven by the IK, in the order targets are given."""
POSE_DOF = 6
"""A chain needs this many joints to track a full 6-D pose; with fewer the IK is position-only."""
MIN_CHAIN_DOF = 3
"""A chain needs at least this many joints to track a 3-D position."""


@dataclass(frozen=True)
class IKConfig:
    """Solver settings."""

    pos_tol: float = 1e-5
    """Stop when every sole is this close to its target position [m] (100x below the 1 mm acceptance)."""
    rot_tol: float = 1e-4
    """... and this close to its target orientation [rad]."""
    max_iters: int = 60
    """Iteration cap per target; a warm-started path sample typically needs 2-3."""
    damping: float = 1e-3
    """Levenberg-Marquardt damping weight on the squared task error [-]."""
    damping_floor: float = 1e-8
    """Minimum damping, keeps the step finite at a singular (straight-knee) configuration [-]."""
    rot_weight: float = 0.3
    """Orientation error weight relative to position [m/rad]: a foot is ~0.3 m from its hip."""
    limit_margin: float = 0.02
    """Iterates are clamped this far inside every joint limit [rad]."""


class FootIK:
    """Frame IK for a fixed-base robot (by default the two soles of a biped).

    Args:
        robot: The robot; must have sites or bodies named as in ``frames``.
        frames: Frame names (sites first, then bodies), one target each.
        config: Solver settings.
        position_only: Drive positions only (3-D targets); ``None``: only when some chain has fewer than
            :data:`POSE_DOF` joints.

    Raises:
        RobotError: one line: a name that is no site or body, a chain too short, or chains sharing a joint.
    """

    def __init__(self, robot: Robot, frames: tuple[str, ...] = SOLES, config: IKConfig | None = None,
                 position_only: bool | None = None):
        import pinocchio as pin

        if robot.base != "fixed":
            raise RobotError(f"{robot.source}: foot IK needs a fixed-base robot (load_robot(..., base='fixed'))")
        frames = tuple(frames)
        if not frames:
            raise RobotError(f"{robot.source}: no IK frame given")
        if len(set(frames)) != len(frames):
            raise RobotError(f"{robot.source}: IK frames {', '.join(frames)} name a frame twice")
        missing = [f for f in frames if f not in robot.frames and f not in robot.body_names]
        if missing:
            have = list(robot.frames) + [b for b in robot.body_names if b not in robot.frames]
            raise RobotError(f"{robot.source}: no site or body named {', '.join(missing)} for the IK targets "
                             f"(--frames); it has {', '.join(have[:12])}{', ...' if len(have) > 12 else ''}")
        self.robot = robot
        self.config = config or IKConfig()
        self.model = build_pinocchio(robot)
        self.data = self.model.createData()
        kind = {f: pin.FrameType.OP_FRAME if f in robot.frames else pin.FrameType.BODY for f in frames}
        self.frame_ids = [self.model.getFrameId(f, kind[f]) for f in frames]
        self.frames = tuple(frames)
        # the DoFs that move each sole: the joints supporting its parent joint
        self.chains = []
        for fid in self.frame_ids:
            joints = self.model.supports[self.model.frames[fid].parentJoint].tolist()[1:]
            self.chains.append(np.array([self.model.joints[j].idx_q for j in joints], dtype=np.int64))
        names = robot.joint_names
        for f, chain in zip(frames, self.chains):
            if len(chain) < MIN_CHAIN_DOF:
                raise RobotError(f"{robot.source}: IK frame {f!r} is moved by {len(chain)} joint(s) "
                                 f"({', '.join(names[i] for i in chain) or 'none'}); it needs at least "
                                 f"{MIN_CHAIN_DOF} to follow a 3-D target")
        for a in range(len(frames)):
            for b in range(a + 1, len(frames)):
                shared = np.intersect1d(self.chains[a], self.chains[b])
                if len(shared):
                    raise RobotError(f"{robot.source}: IK frames {frames[a]!r} and {frames[b]!r} share joint(s) "
                                     f"{', '.join(names[i] for i in shared)}; give frames on separate chains")
        self.dofs = np.unique(np.concatenate(self.chains))
        m = self.config.limit_margin
        self.lower = np.where(np.isfinite(robot.lower), robot.lower + m, -np.pi)
        self.upper = np.where(np.isfinite(robot.upper), robot.upper - m, np.pi)
        self._lower_dofs, self._upper_dofs = self.lower[self.dofs], self.upper[self.dofs]
        self._row_sets: dict = {}
        self._pin = pin
        pose_rank, pos_rank = self._ranks()
        for f, r in zip(frames, pos_rank):
            if r < 3:
                raise RobotError(f"{robot.source}: the joints moving IK frame {f!r} move its position along only {r} "
                                 "direction(s) (a frame on its last joint's axis?); pick a frame further out")
        self.position_only = bool(min(pose_rank) < POSE_DOF if position_only is None else position_only)
        """Targets are positions only (some chain cannot move its frame along all 6 pose directions)."""

    def _ranks(self, samples: int = 8) -> tuple[list[int], list[int]]:
        """Per frame, the rank of its 6-D and of its position Jacobian (over its chain), the largest over a few
        configurations drawn inside the limits (a fixed generator: the excitation's draws are untouched)."""
        pin = self._pin
        rng = np.random.default_rng(0)
        pose, pos = [0] * len(self.frame_ids), [0] * len(self.frame_ids)
        for _ in range(samples):
            q = np.clip(self.robot.q0, self.lower, self.upper)
            q[self.dofs] = rng.uniform(self.lower[self.dofs], self.upper[self.dofs])
            pin.computeJointJacobians(self.model, self.data, q)
            pin.updateFramePlacements(self.model, self.data)
            for i, (fid, chain) in enumerate(zip(self.frame_ids, self.chains)):
                j = pin.getFrameJacobian(self.model, self.data, fid, pin.LOCAL_WORLD_ALIGNED)[:, chain]
                pose[i] = max(pose[i], int(np.linalg.matrix_rank(j, tol=1e-6)))
                pos[i] = max(pos[i], int(np.linalg.matrix_rank(j[:3], tol=1e-6)))
        return pose, pos

    def forward(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sole positions [m], shape (n_frames, 3), and rotation matrices, shape (n_frames, 3, 3), at ``q``."""
        self._pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=np.float64))
        oMf = self.data.oMf
        h = np.array([oMf[f].homogeneous for f in self.frame_ids])  # one copy of both out of Pinocchio
        return h[:, :3, 3].copy(), h[:, :3, :3].copy()

    def _error(self, q, pos, rot):
        p, r = self.forward(q)
        err = np.empty((len(self.frame_ids), 6))
        err[:, :3] = (pos - p) if pos is not None else 0.0
        if self.position_only:
            err[:, 3:] = 0.0  # the orientation is not a target
            return err
        for i in range(len(self.frame_ids)):
            err[i, 3:] = self._pin.log3(rot[i] @ r[i].T)  # world-frame rotation that takes the sole to its target
        return err

    def solve(self, pos: np.ndarray | None, rot: np.ndarray, q_init: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Solve for one set of targets.

        Args:
            pos: Target sole positions in the base (world) frame [m], shape (n_frames, 3); ``None`` solves for
                the orientations alone (the nearest configuration with the given sole orientations; not with
                ``position_only``).
            rot: Target sole orientations (rotation matrices), shape (n_frames, 3, 3); ignored with
                ``position_only`` (``None`` allowed there).
            q_init: Start configuration [rad], shape (n_dof,); non-leg joints are returned unchanged.

        Returns:
            ``(q, err)``: the solution [rad], shape (n_dof,), and the remaining error per frame,
            ``[position error [m], orientation error [rad]]``, shape (n_frames, 2).
        """
        pin, cfg = self._pin, self.config
        if pos is None and self.position_only:
            raise ValueError("position-only IK needs target positions")
        q = np.array(q_init, dtype=np.float64)
        dofs, lower, upper = self.dofs, self._lower_dofs, self._upper_dofs
        q[dofs] = np.clip(q[dofs], lower, upper)
        rows, w_rows, w_col, eye = self._rows(pos is None)
        nf, m = len(self.frame_ids), len(rows)
        # the error of each iterate is the one the loop tests next, and the last one is returned: each configuration's
        # forward kinematics runs once
        err = self._error(q, pos, rot)
        for _ in range(cfg.max_iters):
            norms = _norms(err)
            if (norms[:, 0] < cfg.pos_tol).all() and (norms[:, 1] < cfg.rot_tol).all():
                break
            pin.computeJointJacobians(self.model, self.data, q)
            jac = np.empty((m * nf, len(dofs)))
            for i, fid in enumerate(self.frame_ids):
                # LOCAL_WORLD_ALIGNED: linear rows are the world velocity of the sole origin, matching err
                j = pin.getFrameJacobian(self.model, self.data, fid, pin.LOCAL_WORLD_ALIGNED)
                jac[m * i: m * i + m] = w_col * j[rows][:, dofs]
            e = (err[:, rows] * w_rows).ravel()
            lam = cfg.damping * float(e @ e) + cfg.damping_floor
            dq = jac.T @ np.linalg.solve(jac @ jac.T + lam * eye, e)
            q[dofs] = np.clip(q[dofs] + dq, lower, upper)
            err = self._error(q, pos, rot)
        return q, _norms(err)

    def _rows(self, orientation_only: bool):
        """The error rows a solve drives (position and orientation, the position's alone, or the orientation's
        alone), their weights as a row and as a column, and the identity of the damped system's size; made once per
        kind (a path solves thousands of samples)."""
        key = (self.position_only, orientation_only, self.config)
        if key not in self._row_sets:
            cfg = self.config
            rows = np.arange(3) if self.position_only else np.arange(3, 6) if orientation_only else np.arange(6)
            w = np.array([1.0, 1.0, 1.0, cfg.rot_weight, cfg.rot_weight, cfg.rot_weight])[rows]
            self._row_sets[key] = (rows, w, w[:, None], np.eye(len(rows) * len(self.frame_ids)))
        return self._row_sets[key]

    def solve_path(self, pos: np.ndarray, rot: np.ndarray, q_init: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Solve a target path sample by sample, each warm-started from the previous solution.

        Args:
            pos: Target sole positions [m], shape (T, n_frames, 3).
            rot: Target sole rotations, shape (T, n_frames, 3, 3); ignored (may be ``None``) with ``position_only``.
            q_init: Configuration to start the first sample from [rad], shape (n_dof,).

        Returns:
            ``(q, err)``: joint positions [rad], shape (T, n_dof), and errors, shape (T, n_frames, 2)
            (see :meth:`solve`).
        """
        t_len = len(pos)
        out = np.empty((t_len, self.robot.n_dof))
        errs = np.empty((t_len, len(self.frame_ids), 2))
        q = np.asarray(q_init, dtype=np.float64)
        for k in range(t_len):
            q, errs[k] = self.solve(pos[k], None if rot is None else rot[k], q)
            out[k] = q
        return out, errs


def _norms(err: np.ndarray) -> np.ndarray:
    """The position and orientation error norms of each frame, (k, 2), of its errors ``err`` (k, 6): what
    ``np.linalg.norm`` gives of ``err[:, :3]`` and of ``err[:, 3:]`` (the same operations: the squares, their sum in
    order, the square root), in one pass without its argument checks (the IK tests them at every iterate)."""
    return np.sqrt(np.add.reduce((err * err).reshape(len(err), 2, 3), axis=2))
