"""Recorded trajectories on the simulation device, cut into windows, with the command path's delay and hold.

Every consumer of the replay takes its data from a :class:`TrajectoryBank`: the PPO environment (rows at the
worlds' current times), the gradient fit (random windows) and evaluation (whole trajectories from their first
sample). A :class:`Window` is what one rollout needs: the recorded states (start state and reference), the
commands as recorded (what a residual observes) and the PD targets the simulated drives get, which are the
commands after the actuator delay of the command path.

Command timing (zero-order hold): command k is held during step k, [t_k, t_k+1). With a delay of δ = m + α
steps (m whole steps, 0 ≤ α < 1) the drive sees during step k the command issued δ·dt earlier, which is
c_{k−m−1} for the first α of the step and c_{k−m} for the rest, so the step's PD target is

    target_k = (1 − α) · c_{k−m} + α · c_{k−m−1},

continuous and piecewise linear in δ (differentiable, as the grey-box identification needs). Before a
trajectory's first sample the first command is held, as on a robot that holds its start pose before recording.

Servo joints (:mod:`wresdyn.robot.servo`) then move their internal goal toward the delayed command with at most
``a_max`` (:meth:`TrajectoryBank.set_goal_accel`, :func:`profile_goals`): from rest at the first command, step
``k``'s goal is one :func:`~wresdyn.robot.servo.profile_step` from step ``k − 1``'s toward ``target_k``, computed
over each whole trajectory by a Warp kernel with its adjoint (:mod:`.goal_profile`), so the loss has a gradient in
``a_max`` and the delay.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from .goal_profile import profile_goals

__all__ = ["Window", "TrajectoryBank", "delay_commands", "profile_goals", "servo_goal_accel"]


@dataclass
class Window:
    """B aligned windows of L steps; sample 0 is the start state. Tensors on the simulation device, float32."""

    q: torch.Tensor
    """Recorded joint positions [rad], (B, L + 1, n): the start state, then the reference after each step."""
    qd: torch.Tensor
    """Recorded joint velocities [rad/s], (B, L + 1, n)."""
    qdd: torch.Tensor
    """Recorded joint accelerations [rad/s²], (B, L + 1, n) (only sample 0 is read: the first observation)."""
    cmd: torch.Tensor
    """Commands as recorded [rad], (B, L, n): what the residual observes at each step."""
    target: torch.Tensor
    """PD targets of the simulated drives [rad], (B, L, n): ``cmd`` after the command path's delay."""
    length: torch.Tensor
    """Steps of real data per window, (B,) long; beyond it a window holds its trajectory's last sample."""

    @property
    def steps(self) -> int:
        return self.cmd.shape[1]

    def repeat(self, times: int) -> "Window":
        """The windows stacked ``times`` times along the batch (e.g. PD-only and residual copies)."""
        return Window(*(x.repeat(times, *([1] * (x.dim() - 1))) for x in (self.q, self.qd, self.qdd, self.cmd,
                                                                           self.target, self.length)))

    @classmethod
    def from_arrays(cls, q0, qd0, cmd, device=None, target=None) -> "Window":
        """Windows without a recording (a plain replay): start state q0, qd0 (B, n), commands (B, L, n)."""
        f = lambda x: torch.as_tensor(np.array(x, dtype=np.float32), device=device)  # noqa: E731
        cmd = f(cmd)
        b, steps, n = cmd.shape
        q = torch.zeros(b, steps + 1, n, device=cmd.device)
        qd = torch.zeros_like(q)
        q[:, 0], qd[:, 0] = f(q0), f(qd0)
        return cls(q, qd, torch.zeros_like(q), cmd, cmd if target is None else f(target),
                   torch.full((b,), steps, dtype=torch.long, device=cmd.device))


def delay_commands(q_cmd: torch.Tensor, rows: torch.Tensor, first: torch.Tensor, delay) -> torch.Tensor:
    """PD targets at ``rows`` of a concatenated command table with the delay of the module docstring.

    Args:
        q_cmd: Commands [rad], (R, n): trajectories concatenated along time.
        rows: Row indices of the steps, any shape S (long).
        first: First row of each row's trajectory, same shape as ``rows`` (earlier rows hold the first command).
        delay: δ in steps: a float, or a tensor (n,) per joint (differentiable).

    Returns:
        Targets, shape S + (n,).
    """
    n = q_cmd.shape[1]
    if not torch.is_tensor(delay):
        if delay == 0:
            return q_cmd[rows]
        delay = torch.full((n,), float(delay), device=q_cmd.device)
    # a CUDA graph being captured cannot read the host: there the caller keeps the delay >= 0 (identification's
    # projection)
    if not (delay.is_cuda and torch.cuda.is_current_stream_capturing()) and (delay.detach() < 0).any():
        raise ValueError("the command delay must be >= 0 steps")
    m = torch.floor(delay.detach()).long()  # (n,)
    alpha = delay - m.to(delay.dtype)  # carries the gradient
    r = rows.unsqueeze(-1)
    lo = first.unsqueeze(-1)
    r0 = torch.maximum(r - m, lo)
    r1 = torch.maximum(r - m - 1, lo)
    col = torch.arange(n, device=q_cmd.device).expand_as(r0)
    return (1.0 - alpha) * q_cmd[r0, col] + alpha * q_cmd[r1, col]


def servo_goal_accel(robot, physics, dt: float, device) -> torch.Tensor | None:
    """The goal acceleration [rad/step²] of ``robot``'s servo joints (0 on the others) for a bank at sample period
    ``dt`` [s]: ``physics.goal_accel`` (:class:`~wresdyn.robot.physical.PhysicalParams`), or the robot's own with
    ``physics`` None; ``None`` for a robot without servo drives."""
    servo = getattr(robot, "servo", None)
    if servo is None:
        return None
    accel = servo.goal_accel if physics is None else physics.goal_accel
    return torch.as_tensor(np.where(servo.mask, accel, 0.0) * dt * dt, dtype=torch.float32, device=device)


class TrajectoryBank:
    """Recorded trajectories concatenated along time on the device; row ``start[j] + k`` is sample k of j.

    Args:
        trajectories: Objects with ``q``, ``qd``, ``qdd``, ``q_cmd`` arrays (T_j, n) (a recorded torque is
            never read).
        device: Torch device.
        delay: Actuator delay of the simulated command path [steps], a float or a tensor (n,); see the module
            docstring.
        goal_accel: Servo goal acceleration limit [rad/step²], a tensor (n,) (:func:`servo_goal_accel`), or
            ``None`` for no servo profile.
    """

    def __init__(self, trajectories, device, delay=0.0, goal_accel=None) -> None:
        trajectories = list(trajectories)
        if not trajectories:
            raise ValueError("no trajectories to replay")
        lengths = np.array([len(t.q) for t in trajectories])
        if (lengths < 2).any():
            raise ValueError("every trajectory needs at least two samples")

        def cat(name):
            return torch.as_tensor(np.concatenate([getattr(t, name) for t in trajectories]), dtype=torch.float32,
                                   device=device)

        self.names = [getattr(t, "name", str(i)) for i, t in enumerate(trajectories)]
        self.q, self.qd, self.qdd, self.q_cmd = cat("q"), cat("qd"), cat("qdd"), cat("q_cmd")
        """Recorded q [rad], q̇ [rad/s], q̈ [rad/s²] and commanded q [rad], each (T_total, n)."""
        self._lengths = lengths  # on the host: drawing windows reads them without a device sync
        self.length = torch.as_tensor(lengths, device=device)
        """Samples per trajectory, (J,)."""
        self.start = torch.as_tensor(np.concatenate([[0], np.cumsum(lengths)[:-1]]), device=device)
        """First row of each trajectory, (J,)."""
        self.first = torch.repeat_interleave(self.start, self.length)
        """First row of each row's trajectory, (T_total,)."""
        self.device = self.q.device
        self.delay = self.goal_accel = self._fixed = None
        self.set_command_path(delay, goal_accel)

    @property
    def n_trajectories(self) -> int:
        return len(self.length)

    def set_delay(self, delay) -> None:
        """Set the command delay [steps]; a constant delay is applied once to the whole table."""
        self.set_command_path(delay, self.goal_accel)

    def set_goal_accel(self, accel) -> None:
        """Set the servo goal acceleration limit per joint [rad/step²], a tensor (n,) (0 on joints without a profile),
        or ``None`` for none (see the module docstring)."""
        self.set_command_path(self.delay, accel)

    def set_command_path(self, delay, goal_accel) -> None:
        """Set the delay [steps] and the servo goal acceleration [rad/step²] (or ``None``) together; without
        gradients to either, the targets are computed once for the whole table."""
        same = goal_accel is not None and self._same(delay, self.delay) and self._same(goal_accel, self.goal_accel)
        self.delay = delay
        self.goal_accel = None if goal_accel is None else torch.as_tensor(goal_accel, device=self.device)
        if self.goal_accel is not None:
            if not (same and self._fixed is not None):  # the profile runs over every sample: only when it changed
                self._fixed = None if self._grad() else self._profiled()
            return
        self._fixed = None if torch.is_tensor(delay) and delay.requires_grad else delay_commands(
            self.q_cmd, torch.arange(len(self.q_cmd), device=self.device), self.first, delay)

    @staticmethod
    def _same(a, b) -> bool:
        """Whether two delays or goal accelerations are the same values without gradients."""
        if torch.is_tensor(a) != torch.is_tensor(b):
            return False
        if not torch.is_tensor(a):
            return a == b
        return not (a.requires_grad or b.requires_grad) and a.shape == b.shape and bool(torch.equal(a, b.to(a.device)))

    def _grad(self) -> bool:
        return any(torch.is_tensor(x) and x.requires_grad for x in (self.delay, self.goal_accel))

    def _profiled(self) -> torch.Tensor:
        rows = torch.arange(len(self.q_cmd), device=self.device)
        return profile_goals(delay_commands(self.q_cmd, rows, self.first, self.delay), self.first, self.goal_accel)

    def target(self, rows: torch.Tensor) -> torch.Tensor:
        """PD targets (delayed commands, servo goals after their profile) at ``rows`` [rad], shape rows.shape + (n,)."""
        if self._fixed is not None:
            return self._fixed[rows]
        if self.goal_accel is not None:
            return self._profiled()[rows]
        return delay_commands(self.q_cmd, rows, self.first[rows], self.delay)

    def rows(self, traj: torch.Tensor, start: torch.Tensor, steps: int) -> torch.Tensor:
        """Rows of windows of ``steps`` steps from sample ``start`` of trajectory ``traj`` (B,): (B, steps + 1),
        clamped to each trajectory's last sample (a window past the end holds it)."""
        k = torch.arange(steps + 1, device=self.device)
        last = (self.start[traj] + self.length[traj] - 1)[:, None]
        return torch.minimum(self.start[traj][:, None] + start[:, None] + k[None], last)

    def window(self, traj: torch.Tensor, start: torch.Tensor, steps: int) -> Window:
        """Windows of ``steps`` steps from sample ``start`` (B,) of trajectories ``traj`` (B,)."""
        rows = self.rows(traj, start, steps)
        length = torch.clamp(self.length[traj] - 1 - start, max=steps)
        return Window(self.q[rows], self.qd[rows], self.qdd[rows], self.q_cmd[rows[:, :-1]],
                      self.target(rows[:, :-1]), length)

    def whole(self) -> Window:
        """Every trajectory from its first sample to the end of the longest (shorter ones hold their last)."""
        traj = torch.arange(self.n_trajectories, device=self.device)
        return self.window(traj, torch.zeros_like(traj), int(self.length.max()) - 1)

    def draw(self, rng: np.random.Generator, b: int, steps: int) -> tuple[torch.Tensor, torch.Tensor]:
        """``b`` (trajectory, start) pairs of windows of ``steps`` steps, uniform over those that fit: (B,) each."""
        lengths = self._lengths
        eligible = np.flatnonzero(lengths > steps)
        if len(eligible) == 0:
            raise ValueError(f"every trajectory is shorter than the {steps + 1} samples a window needs")
        traj = eligible[rng.integers(0, len(eligible), b)]
        start = rng.integers(0, lengths[traj] - steps, b)
        return _to_device(traj, self.device), _to_device(start, self.device)

    def sample(self, rng: np.random.Generator, b: int, steps: int) -> Window:
        """``b`` windows of ``steps`` steps drawn uniformly over all (trajectory, start) pairs that fit."""
        return self.window(*self.draw(rng, b, steps), steps)


def _to_device(x: np.ndarray, device: torch.device) -> torch.Tensor:
    """A host array on ``device``; to CUDA through pinned memory, so the copy does not wait for the work already
    queued on the stream (a pageable copy would)."""
    t = torch.as_tensor(x)
    if device.type != "cuda":
        return t.to(device)
    return t.pin_memory().to(device, non_blocking=True)
