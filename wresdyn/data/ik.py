"""Inverse kinematics of both soles on a fixed base, with Pinocchio.

Each sole site (``left_sole``, ``right_sole``) is driven to a full 6-D target (position and orientation), so
a 6-DoF leg has a locally unique solution and no null-space drift. Both legs are solved together as one
damped least-squares problem (Levenberg-Marquardt: the damping grows with the squared error, so steps are
Gauss-Newton near the solution and cautious far from it), every iterate is clamped into the joint limits,
and a path is solved sample by sample warm-started from the previous solution, which keeps the command
sequence smooth. Joints outside the legs are not moved.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..robot.description import Robot, RobotError

__all__ = ["FootIK", "IKConfig", "SOLES"]

SOLES = ("left_sole", "right_sole")
"""Sole frames driven by the IK, in the order targets are given."""


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
    """Sole-frame IK for a fixed-base biped.

    Args:
        robot: The robot; must have the sites named in ``frames``.
        frames: Sole frame names, one target each.
        config: Solver settings.
    """

    def __init__(self, robot: Robot, frames: tuple[str, ...] = SOLES, config: IKConfig | None = None):
        import pinocchio as pin

        from ..robot.pinocchio_model import build_pinocchio

        if robot.base != "fixed":
            raise RobotError(f"{robot.source}: foot IK needs a fixed-base robot (load_robot(..., base='fixed'))")
        missing = [f for f in frames if f not in robot.frames]
        if missing:
            raise RobotError(f"{robot.source}: no site named {', '.join(missing)} (needed for foot IK)")
        self.robot = robot
        self.config = config or IKConfig()
        self.model = build_pinocchio(robot)
        self.data = self.model.createData()
        self.frame_ids = [self.model.getFrameId(f) for f in frames]
        self.frames = tuple(frames)
        # the DoFs that move each sole: the joints supporting its parent joint
        self.chains = []
        for fid in self.frame_ids:
            joints = self.model.supports[self.model.frames[fid].parentJoint].tolist()[1:]
            self.chains.append(np.array([self.model.joints[j].idx_q for j in joints], dtype=np.int64))
        self.dofs = np.unique(np.concatenate(self.chains))
        m = self.config.limit_margin
        self.lower = np.where(np.isfinite(robot.lower), robot.lower + m, -np.pi)
        self.upper = np.where(np.isfinite(robot.upper), robot.upper - m, np.pi)
        self._pin = pin

    def forward(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sole positions [m], shape (n_frames, 3), and rotation matrices, shape (n_frames, 3, 3), at ``q``."""
        pin = self._pin
        pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=np.float64))
        pos = np.array([self.data.oMf[f].translation for f in self.frame_ids])
        rot = np.array([self.data.oMf[f].rotation for f in self.frame_ids])
        return pos, rot

    def _error(self, q, pos, rot):
        p, r = self.forward(q)
        err = np.empty((len(self.frame_ids), 6))
        err[:, :3] = (pos - p) if pos is not None else 0.0
        for i in range(len(self.frame_ids)):
            err[i, 3:] = self._pin.log3(rot[i] @ r[i].T)  # world-frame rotation that takes the sole to its target
        return err

    def solve(self, pos: np.ndarray | None, rot: np.ndarray, q_init: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Solve for one set of targets.

        Args:
            pos: Target sole positions in the base (world) frame [m], shape (n_frames, 3); ``None`` solves for
                the orientations alone (the nearest configuration with the given sole orientations).
            rot: Target sole orientations (rotation matrices), shape (n_frames, 3, 3).
            q_init: Start configuration [rad], shape (n_dof,); non-leg joints are returned unchanged.

        Returns:
            ``(q, err)``: the solution [rad], shape (n_dof,), and the remaining error per frame,
            ``[position error [m], orientation error [rad]]``, shape (n_frames, 2).
        """
        pin, cfg = self._pin, self.config
        q = np.array(q_init, dtype=np.float64)
        q[self.dofs] = np.clip(q[self.dofs], self.lower[self.dofs], self.upper[self.dofs])
        rows = np.arange(6) if pos is not None else np.arange(3, 6)
        w = np.array([1.0, 1.0, 1.0, cfg.rot_weight, cfg.rot_weight, cfg.rot_weight])
        nf = len(self.frame_ids)
        for _ in range(cfg.max_iters):
            err = self._error(q, pos, rot)
            if (np.linalg.norm(err[:, :3], axis=1) < cfg.pos_tol).all() and (
                    np.linalg.norm(err[:, 3:], axis=1) < cfg.rot_tol).all():
                break
            pin.computeJointJacobians(self.model, self.data, q)
            m = len(rows)
            jac = np.zeros((m * nf, len(self.dofs)))
            for i, fid in enumerate(self.frame_ids):
                # LOCAL_WORLD_ALIGNED: linear rows are the world velocity of the sole origin, matching err
                j = pin.getFrameJacobian(self.model, self.data, fid, pin.LOCAL_WORLD_ALIGNED)
                jac[m * i: m * i + m] = (w[:, None] * j[:, self.dofs])[rows]
            e = (w * err)[:, rows].ravel()
            lam = cfg.damping * float(e @ e) + cfg.damping_floor
            dq = jac.T @ np.linalg.solve(jac @ jac.T + lam * np.eye(m * nf), e)
            q[self.dofs] = np.clip(q[self.dofs] + dq, self.lower[self.dofs], self.upper[self.dofs])
        err = self._error(q, pos, rot)
        return q, np.stack([np.linalg.norm(err[:, :3], axis=1), np.linalg.norm(err[:, 3:], axis=1)], axis=1)

    def solve_path(self, pos: np.ndarray, rot: np.ndarray, q_init: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Solve a target path sample by sample, each warm-started from the previous solution.

        Args:
            pos: Target sole positions [m], shape (T, n_frames, 3).
            rot: Target sole rotations, shape (T, n_frames, 3, 3).
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
            q, errs[k] = self.solve(pos[k], rot[k], q)
            out[k] = q
        return out, errs
