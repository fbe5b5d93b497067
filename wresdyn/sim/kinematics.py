"""World positions of every body of a floating-base robot, batched: Newton's forward kinematics (``newton.eval_fk``).

Used where a learner or a metric needs link positions from a state it holds as tensors (the feet of a skill on
the floor, every link for the global body-position error), whatever stepped the state (Newton, MuJoCo C).
"""

from __future__ import annotations

import torch

from ..robot.ground import base_index

__all__ = ["BodyPositions"]


class BodyPositions:
    """Forward kinematics of ``num_worlds`` copies of a floating-base ``robot`` on ``device``.

    ``__call__(base_pose (N, 7), q (N, n)) -> (N, n_bodies, 3)``: body-frame origins in the world [m]
    (Newton's free-joint convention, :mod:`wresdyn.robot.ground`; ``N <= num_worlds``).
    """

    def __init__(self, robot, num_worlds: int, device: str = "cpu") -> None:
        import warp as wp

        self.robot, self.num_worlds = robot, int(num_worlds)
        self.model = robot.build_model(self.num_worlds, device)
        self.state = self.model.state()
        self.device = torch.device(str(wp.device_to_torch(self.model.device)))
        w = self.num_worlds
        self.nq = self.model.joint_coord_count // w
        self.nb = self.model.body_count // w
        q0 = base_index(robot)[0]
        self._base = slice(q0, q0 + 7)
        self._q_index = torch.as_tensor(robot.q_index, device=self.device)
        self._joint_q = wp.to_torch(self.state.joint_q, requires_grad=False).view(w, self.nq)
        self._body_q = wp.to_torch(self.state.body_q, requires_grad=False).view(w, self.nb, 7)

    def __call__(self, base_pose: torch.Tensor, q: torch.Tensor) -> torch.Tensor:
        import newton

        k = len(q)
        if k > self.num_worlds:
            raise ValueError(f"{k} states, BodyPositions holds {self.num_worlds} worlds")
        self._joint_q[:k, self._base] = base_pose.to(self.device, torch.float32)
        self._joint_q[:k, self._q_index] = q.to(self.device, torch.float32)
        newton.eval_fk(self.model, self.state.joint_q, self.state.joint_qd, self.state)
        return self._body_q[:k, :, :3].clone()
