"""The "real" robot batched on a GPU: :class:`RealWarpPlant`, the worlds of
:class:`~wresdyn.skills.plants.RealPlant` stepped by mujoco_warp instead of MuJoCo C.

The oracle policy trains on the real robot itself. On MuJoCo C (``mujoco.rollout`` in host threads) its worlds cost
10-15x those of the simulated plants on a GPU, so the oracle trained on fewer of them; here the same MuJoCo model
(the mismatch's, :class:`~wresdyn.data.real_robot.RealRobot`) runs in mujoco_warp, every world on the device, so
the oracle trains with the worlds and iterations of the other policies. Deployment stays on
:class:`~wresdyn.skills.plants.RealPlant` (MuJoCo C in float64: the robot a policy is judged on).

What is the same as :class:`~wresdyn.skills.plants.RealPlant`: the model (mismatched physics, torque limits as
actuator force ranges, the floor's contact), the integrator (``implicitfast``) and physics substep, the delay line
(a FIFO of ``n_delay`` commands at the substep), a cold constraint-solver warm start at every step, the sensors (noise
and quantisation of the mismatch) and the IMU. What differs: mujoco_warp computes in float32 (MuJoCo C in float64), so
trajectories drift apart where the dynamics amplify round-off (contact, stiction); the model is copied to the device
at construction (a later change of ``real.model`` is not seen); the noise comes from torch's generator, not numpy's;
no record of the drive torques and states within a step (RealPlant's ``tau``, ``q_samples``: deployment metrics, not
read in training); PD drives only (a servo drive's law changes the model every substep).
"""

from __future__ import annotations

import contextlib
import functools

import numpy as np
import torch

from ..errors import WresdynError
from ..sim.floor_budget import collision_geoms_mujoco, floor_budget
from .reference import base_frame_imu, quat_rotate_inv

__all__ = ["RealWarpPlant", "free_from_mujoco_t", "free_to_mujoco_t", "sense"]



def _quat_rotate(quat_xyzw: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate vectors ``v`` (N, 3) of the frames ``quat_xyzw`` (N, 4) into world axes."""
    return quat_rotate_inv(torch.cat([-quat_xyzw[:, :3], quat_xyzw[:, 3:]], -1), v)


def free_to_mujoco_t(com: torch.Tensor, base_pose: torch.Tensor, base_twist: torch.Tensor
                     ) -> tuple[torch.Tensor, torch.Tensor]:
    """:func:`wresdyn.robot.mujoco_model.free_to_mujoco` on the device: Newton's base pose [x y z qx qy qz qw]
    (N, 7) and twist [centre-of-mass velocity, angular velocity] in world axes (N, 6) -> MuJoCo's free joint
    ``qpos`` [x y z qw qx qy qz] (N, 7) and ``qvel`` [body-origin velocity in world axes, angular velocity in body
    axes] (N, 6). ``com``: the base's centre of mass in its body frame [m] (N, 3)."""
    quat, w = base_pose[:, 3:], base_twist[:, 3:]
    v_origin = base_twist[:, :3] - torch.cross(w, _quat_rotate(quat, com), dim=-1)
    qpos = torch.cat([base_pose[:, :3], quat[:, 3:], quat[:, :3]], -1)
    return qpos, torch.cat([v_origin, quat_rotate_inv(quat, w)], -1)


def free_from_mujoco_t(com: torch.Tensor, qpos: torch.Tensor, qvel: torch.Tensor
                       ) -> tuple[torch.Tensor, torch.Tensor]:
    """The inverse of :func:`free_to_mujoco_t` (:func:`wresdyn.robot.mujoco_model.free_from_mujoco` on the
    device): MuJoCo's ``qpos[:, :7]``, ``qvel[:, :6]`` -> Newton's ``(base_pose (N, 7), base_twist (N, 6))``."""
    quat = torch.cat([qpos[:, 4:7], qpos[:, 3:4]], -1)
    w = _quat_rotate(quat, qvel[:, 3:6])
    v_com = qvel[:, :3] + torch.cross(w, _quat_rotate(quat, com), dim=-1)
    return torch.cat([qpos[:, :3], quat], -1), torch.cat([v_com, w], -1)


def sense(mismatch, q: torch.Tensor, qd: torch.Tensor, gen: torch.Generator | None
          ) -> tuple[torch.Tensor, torch.Tensor]:
    """What the encoders report for the true ``q``, ``qd`` [rad, rad/s] (..., n): the law of
    :meth:`~wresdyn.data.real_robot.RealRobot.sense` (the ``mismatch``'s white noise, drawn from ``gen``, then its
    quantisation) on torch tensors."""
    out = []
    for x, noise, res in ((q, mismatch.position_noise, mismatch.encoder_resolution),
                          (qd, mismatch.velocity_noise, mismatch.velocity_resolution)):
        if noise > 0:
            x = x + noise * torch.randn(x.shape, generator=gen, device=x.device, dtype=x.dtype)
        out.append(torch.round(x / res) * res if res > 0 else x.clone())
    return out[0], out[1]


@functools.cache
def _command_kernel():
    """The Warp kernel that sets every world's ctrl to column ``j`` of the delay line (a launch a graph can hold)."""
    import warp as wp

    @wp.kernel
    def command_at(line_in: wp.array3d(dtype=float), j: int, ctrl_out: wp.array2d(dtype=float)):
        w, i = wp.tid()
        ctrl_out[w, i] = line_in[w, j, i]

    return command_at


class RealWarpPlant:
    """``num_worlds`` copies of the "real" robot in mujoco_warp: on its stand (fixed base) or standing on its floor.

    The interface of :class:`~wresdyn.skills.plants.RealPlant` (``reset``, ``reset_full``, ``step``, ``base_pose``,
    ``base_twist``, ``imu``, ``q_true``, ``qd_true``), every state a torch tensor on ``device`` sharing the memory
    of mujoco_warp's arrays; a step stays on the device (no host synchronisation).

    Args:
        real: The real robot (:class:`~wresdyn.data.real_robot.RealRobot`); its MuJoCo model as it is now.
        num_worlds: Worlds.
        decimation: Recording periods per :meth:`step` (the policy period is ``decimation / real.rate_hz``).
        seed: Seed of the sensor and IMU noise.
        imu_noise: Standard deviations of the IMU's white noise: angular velocity [rad/s] and the measured gravity
            direction [-] (floor only).
        device: Warp / torch device (``None``: ``cuda:0`` when a GPU is visible, else ``cpu``).
        graph: Replay a step's physics substeps as one captured Warp graph (CUDA graph on a GPU), captured at the
            first step: no launch overhead per kernel, and the solver's iterations stop at convergence inside the
            graph without a host round trip. Off: every kernel launched from Python (20-50x slower on the CPU).

    Example:
        >>> plant = RealWarpPlant(RealRobot(floating, mismatch), 4096, 10, device="cuda:0")
        >>> plant.reset_full(ids, base_pose, base_twist, q, qd)
        >>> q, qd, diverged = plant.step(cmd)
    """

    def __init__(self, real, num_worlds: int, decimation: int, seed: int = 0,
                 imu_noise: tuple[float, float] = (0.0, 0.0), device: str | None = None,
                 graph: bool = True) -> None:
        import mujoco_warp as mjw
        import warp as wp

        if real.robot.servo is not None:
            raise WresdynError(f"{real.robot.source.name}: the mujoco_warp real robot drives PD joints only; "
                               "servo drives change the model every physics step (use the MuJoCo C plant)")
        self.real, self.num_worlds, self.decimation = real, int(num_worlds), int(decimation)
        self.robot, self.floating = real.robot, bool(real.floating)
        self.imu_noise = tuple(float(x) for x in imu_noise)
        if device is None:
            device = "cuda:0" if wp.is_cuda_available() else "cpu"
        self._wp, self._mjw = wp, mjw
        self._wp_device = wp.get_device(device)
        self.device = torch.device(str(self._wp_device))
        m = real.model
        n = self.robot.n_dof
        if m.nu != n:
            raise WresdynError(f"{real.robot.source.name}: {m.nu} actuators for {n} joints")
        # the same contacts and constraint rows per world as wresdyn's floor solver (see wresdyn.sim.floor_budget)
        nconmax, njmax = floor_budget(collision_geoms_mujoco(m), m.nv)
        with wp.ScopedDevice(self._wp_device):
            self.model = mjw.put_model(m)
            self.data = mjw.make_data(m, nworld=self.num_worlds, nconmax=nconmax, njmax=njmax)
        view = wp.to_torch
        self._qpos, self._qvel = view(self.data.qpos), view(self.data.qvel)
        """MuJoCo's state (N, nq), (N, nv) float32, the device's memory: base (floor) then joints."""
        self._b = 7 if self.floating else 0  # the joints' first qpos
        self._bv = 6 if self.floating else 0
        self.n_sub = real.n_sub * self.decimation
        """Physics substeps per :meth:`step`."""
        self._fifo = torch.zeros(self.num_worlds, real.n_delay, n, device=self.device)
        """The commands on their way to the motors [rad] (N, n_delay, n), oldest first: the delay line."""
        self._line = wp.zeros((self.num_worlds, self.n_sub, n), dtype=float, device=self._wp_device)
        """What reaches the motors at each physics substep of a step [rad] (N, n_sub, n)."""
        self._line_t = view(self._line)
        self._com = torch.as_tensor(np.asarray(self.robot.body_com[0]), dtype=torch.float32,
                                    device=self.device).expand(self.num_worlds, 3)
        self.graph = bool(graph)
        """Whether the physics of a step replays as a captured graph."""
        self._graph = None
        self._stream = wp.get_stream(self._wp_device) if self.device.type == "cuda" else None
        self.gen = torch.Generator(device=self.device)
        self.gen.manual_seed(int(seed))
        self.q_true = torch.zeros(self.num_worlds, n, device=self.device)
        """True joint positions [rad] after the last step or reset (N, n)."""
        self.qd_true = torch.zeros_like(self.q_true)
        """True joint velocities [rad/s] (N, n)."""

    def _substeps(self) -> None:
        """The physics of one step: every substep's command from the delay line, then mujoco_warp's step; the
        constraint solver starts cold, as RealPlant's rollout does at every step."""
        wp, kernel = self._wp, _command_kernel()
        self.data.qacc_warmstart.zero_()
        for j in range(self.n_sub):
            wp.launch(kernel, dim=(self.num_worlds, self.robot.n_dof), inputs=[self._line, j],
                      outputs=[self.data.ctrl], device=self._wp_device)
            self._mjw.step(self.model, self.data)

    def _physics(self) -> None:
        """Run :meth:`_substeps` on the device, as a graph when :attr:`graph` (captured at the first call, after an
        eager one that loads the kernels); on a GPU on Warp's stream, ordered after torch's work on the shared arrays
        and before torch's next."""
        wp = self._wp
        with wp.ScopedDevice(self._wp_device), contextlib.ExitStack() as stack:
            if self._stream is not None:
                torch_stream = wp.stream_from_torch(self.device)
                self._stream.wait_stream(torch_stream)
                stack.enter_context(wp.ScopedStream(self._stream))
            if self._graph is not None:
                wp.capture_launch(self._graph)
            else:
                self._substeps()
                if self.graph:
                    with wp.ScopedCapture(self._wp_device) as capture:
                        self._substeps()
                    self._graph = capture.graph
            if self._stream is not None:
                torch_stream.wait_stream(self._stream)

    def _t(self, x) -> torch.Tensor:
        return torch.as_tensor(x).to(self.device, torch.float32)

    def reset(self, ids, q, qd) -> None:
        """Place worlds ``ids`` at ``q``, ``qd`` [rad, rad/s] (k, n); the delay line holds ``q``."""
        if self.floating:
            raise ValueError(f"{self.robot.source.name}: a robot on the floor is placed with reset_full")
        self._reset(ids, q, qd)

    def reset_full(self, ids, base_pose, base_twist, q, qd) -> None:
        """Place worlds ``ids`` of the robot on the floor: base pose (k, 7), twist (k, 6) in Newton's free-joint
        convention (:mod:`wresdyn.robot.ground`), joints ``q``, ``qd`` (k, n); the delay line holds ``q``."""
        if len(ids) == 0:
            return
        pose = self._t(base_pose)
        base_qpos, base_qvel = free_to_mujoco_t(self._com[:len(pose)], pose, self._t(base_twist))
        self._reset(ids, q, qd, base_qpos, base_qvel)

    def _reset(self, ids, q, qd, base_qpos=None, base_qvel=None) -> None:
        ids = torch.as_tensor(ids, device=self.device).long()
        if len(ids) == 0:
            return
        q, qd = self._t(q), self._t(qd)
        if self.floating:
            self._qpos[ids, :7], self._qvel[ids, :6] = base_qpos, base_qvel
        self._qpos[ids, self._b:], self._qvel[ids, self._bv:] = q, qd
        self._fifo[ids] = q[:, None, :]
        self.q_true[ids], self.qd_true[ids] = q, qd

    @property
    def base_pose(self) -> torch.Tensor:
        """True base pose per world [x y z qx qy qz qw] (N, 7), float32 (floor only)."""
        return self._base()[0]

    @property
    def base_twist(self) -> torch.Tensor:
        """True base centre-of-mass velocity [m/s] and angular velocity [rad/s], world axes (N, 6) (floor only)."""
        return self._base()[1]

    def _base(self) -> tuple[torch.Tensor, torch.Tensor]:
        return free_from_mujoco_t(self._com, self._qpos[:, :7], self._qvel[:, :6])

    def imu(self) -> tuple[torch.Tensor, torch.Tensor]:
        """What the base IMU reports: angular velocity [rad/s] and the unit gravity direction, both in base axes,
        (N, 3) each, with ``imu_noise``."""
        gyro, grav = base_frame_imu(self.base_pose, self.base_twist)
        sg, sd = self.imu_noise
        if sg > 0:
            gyro = gyro + sg * torch.randn(gyro.shape, generator=self.gen, device=self.device)
        if sd > 0:
            grav = grav + sd * torch.randn(grav.shape, generator=self.gen, device=self.device)
            grav = grav / grav.norm(dim=-1, keepdim=True)
        return gyro, grav

    def step(self, cmd) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Hold ``cmd`` [rad] (N, n) for ``decimation`` recording periods; returns the sensed ``(q, qd)`` and
        ``diverged`` (bool (N,), a non-finite state: those worlds are left as before the step)."""
        cmd = self._t(cmd)
        line = torch.cat([self._fifo, cmd[:, None].expand(-1, self.n_sub, -1)], 1)  # reaching the motors, oldest first
        qpos0, qvel0 = self._qpos.clone(), self._qvel.clone()
        self._line_t.copy_(line[:, :self.n_sub])
        self._physics()
        self._fifo = line[:, self.n_sub:].clone()
        bad = ~(torch.isfinite(self._qpos).all(-1) & torch.isfinite(self._qvel).all(-1))
        self._qpos.copy_(torch.where(bad[:, None], qpos0, self._qpos))
        self._qvel.copy_(torch.where(bad[:, None], qvel0, self._qvel))
        self.q_true = self._qpos[:, self._b:].clone()
        self.qd_true = self._qvel[:, self._bv:].clone()
        q, qd = sense(self.real.mismatch, self.q_true, self.qd_true, self.gen)
        return q, qd, bad
