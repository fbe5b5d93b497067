"""The robots a skill policy acts on: N batched copies of one robot, held for one policy period per step.

Every plant has the same interface, so one environment (:mod:`wresdyn.skills.env`) trains and deploys on any of them:
``reset(ids, q, qd)``, ``step(cmd) -> (q, qd)`` (the command [rad], (N, n), held for ``decimation`` sample periods),
``num_worlds`` (the world count: the environment and PPO read it here), ``device``.

- :class:`SimPlant`: the one simulation layer (:class:`wresdyn.sim.Simulator`), in three settings:
  *nominal* (the robot file), *calibrated* (``wresdyn fit``'s run: identified physics, its command delay and the torque
  residual on top, the hybrid) and *delta action* (an ASAP-style residual on the PD target, on the robot file's
  physics). The residual network runs at the sample rate, observing [q, q̇, q̈, q_cmd] as when it was fitted.
- :class:`RealPlant`: the "real" robot (:class:`wresdyn.data.real_robot.RealRobot`, MuJoCo C with the mismatch), the
  worlds stepped by ``mujoco.rollout`` in C threads, the command through the real robot's delay line and torque
  limits, the joint state read through its sensors (noise, quantisation). It is where policies are deployed, and the
  oracle's training ground.
"""

from __future__ import annotations

import os

import numpy as np
import torch

from ..errors import WresdynError
from ..learn.runs import run_physics
from ..learn.run_residual import load_policy
from ..robot.mujoco_model import free_from_mujoco, free_to_mujoco
from ..sim import DivergenceLimits, Simulator
from ..sim.physics import PhysicalParams
from .randomize import Randomization, Randomizer, wide_ranges
from .reference import base_frame_imu

__all__ = ["SimPlant", "RealPlant", "SETTINGS", "sim_plant"]

SETTINGS = ("nominal", "calibrated", "delta_action")
"""The simulated settings a skill is trained in (:func:`sim_plant`)."""


class SimPlant:
    """``num_worlds`` Newton worlds of ``robot`` under PD, optionally with identified physics, a command delay and a
    residual network (torque or delta action) in the loop at the sample rate.

    Args:
        robot: The robot (fixed base).
        num_worlds: Worlds.
        rate_hz: Sample rate [Hz] of the simulation (and of the residual).
        decimation: Sample periods per :meth:`step` (the policy period is ``decimation / rate_hz``).
        physics: :class:`~wresdyn.sim.physics.PhysicalParams` (identified) or ``None`` (the robot file's).
        residual: The residual ``policy(obs (N, 4n)) -> (N, n)`` (a run's ``policy.pt``) or ``None``.
        kind: The residual's kind, ``"torque"`` or ``"delta_action"``.
        device: Warp device.
        ground: The robot (a floating base) stands on a floor (:class:`~wresdyn.sim.Simulator` ``ground=True``):
            :meth:`reset_full` places it, :attr:`base_pose` / :attr:`base_twist` read its base.
        randomization: Domain randomisation (:mod:`wresdyn.skills.randomize`): a
            :class:`~wresdyn.skills.randomize.Randomization` (its wide ranges around ``physics``), or one with the
            :class:`~wresdyn.skills.randomize.Ranges` to draw, ``(cfg, ranges)``; ``None``: every world the same.
    """

    def __init__(self, robot, num_worlds: int, rate_hz: float, decimation: int, *, physics=None, residual=None,
                 kind: str | None = None, device: str = "cpu", solver: str = "auto", ground: bool = False,
                 randomization=None) -> None:
        self.robot, self.num_worlds, self.decimation = robot, int(num_worlds), int(decimation)
        self.dt = 1.0 / rate_hz
        self.sim = Simulator(robot, self.num_worlds, self.dt, solver=solver, device=device, ground=ground)
        self.device = self.sim.device
        n = robot.n_dof
        delay = np.zeros(n)
        if physics is not None:
            self.sim.set_physics(physics)
            delay = np.asarray(physics.delay, dtype=np.float64) * rate_hz  # [samples]
        self.rate_hz = float(rate_hz)
        self.randomizer = None
        longest = float(delay.max())  # [samples]
        if randomization is not None:
            cfg, ranges = randomization if isinstance(randomization, tuple) else (randomization, None)
            if not isinstance(cfg, Randomization):
                raise WresdynError(f"randomization: need a Randomization, got {type(cfg).__name__}")
            centre = physics if physics is not None else PhysicalParams.nominal(robot)
            ranges = ranges or wide_ranges(cfg, robot, centre)
            self.randomizer = Randomizer(self.sim, centre, ranges, seed=cfg.seed)
            self._redraw = cfg.redraw == "reset"
            longest = max(longest, float(np.max(ranges.delay[1])) * rate_hz)
        self._m = torch.as_tensor(np.tile(np.floor(delay), (self.num_worlds, 1)).astype(np.int64),
                                  device=self.device)
        self._alpha = torch.as_tensor(np.tile(delay - np.floor(delay), (self.num_worlds, 1)),
                                      dtype=torch.float32, device=self.device)
        """Per world and joint, the delay's whole sample periods (N, n) and the fraction of one (N, n)."""
        self._hist = torch.zeros(self.num_worlds, int(np.floor(longest)) + 2, n, device=self.device)
        """Commands of the last sample periods [rad], newest first (N, H, n): the delay line."""
        if self.randomizer is not None:
            self._set_delay(torch.arange(self.num_worlds), self.randomizer.draw())
        self.residual = None if residual is None else residual.to(self.device)
        self.kind = kind
        if residual is not None and kind not in ("torque", "delta_action"):
            raise WresdynError(f"residual kind {kind!r}: need 'torque' or 'delta_action'")
        self.limits = DivergenceLimits()
        self.q = torch.zeros(self.num_worlds, n, device=self.device)
        self.qd = torch.zeros_like(self.q)
        self._qdd = torch.zeros_like(self.q)

    def reset(self, ids: torch.Tensor, q: torch.Tensor, qd: torch.Tensor) -> None:
        """Place worlds ``ids`` (long (k,)) at rest-held state ``q``, ``qd`` (k, n); the delay line holds ``q``."""
        if len(ids) == 0:
            return
        if self.randomizer is not None and self._redraw:
            self._set_delay(ids, self.randomizer.draw(ids))
        self.sim.set_state(ids, q, qd)
        self.q[ids], self.qd[ids], self._qdd[ids] = q, qd, 0.0
        self._hist[ids] = q[:, None, :]

    def reset_full(self, ids: torch.Tensor, base_pose: torch.Tensor, base_twist: torch.Tensor, q: torch.Tensor,
                   qd: torch.Tensor) -> None:
        """Place worlds ``ids`` of a robot on the floor: base pose (k, 7) and twist (k, 6) as
        :attr:`wresdyn.sim.Simulator.base_pose`, joints at ``q``, ``qd`` (k, n); the delay line holds ``q``."""
        if len(ids) == 0:
            return
        self.sim.set_full_state(ids, base_pose, base_twist, q, qd)
        self.reset(ids, q, qd)

    def _set_delay(self, ids, seconds: np.ndarray) -> None:
        """Worlds ``ids``' command delay [s] (k, n) into the delay line."""
        d = torch.as_tensor(np.asarray(seconds) * self.rate_hz, dtype=torch.float32, device=self.device)
        whole = torch.floor(d)
        ids = torch.as_tensor(ids, device=self.device)
        self._m[ids], self._alpha[ids] = whole.long(), d - whole

    @property
    def base_pose(self) -> torch.Tensor:
        """Base pose per world [x y z qx qy qz qw] (N, 7) (a robot on the floor)."""
        return self.sim.base_pose

    @property
    def base_twist(self) -> torch.Tensor:
        """Base centre-of-mass velocity [m/s] and angular velocity [rad/s], world axes (N, 6)."""
        return self.sim.base_twist

    def step(self, cmd: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Hold ``cmd`` [rad] (N, n) for ``decimation`` sample periods; returns ``(q, qd, diverged)`` at the end
        ([rad], [rad/s], bool (N,): worlds that ran away, their state left as it was before the step)."""
        q, qd, qdd = self.q, self.qd, self._qdd
        for _ in range(self.decimation):
            self._hist = torch.roll(self._hist, 1, dims=1)
            self._hist[:, 0] = cmd
            a = self._alpha
            m = self._m[:, None, :]
            target = (1 - a) * self._hist.gather(1, m)[:, 0] + a * self._hist.gather(1, m + 1)[:, 0]
            tau = None
            if self.residual is not None:
                with torch.no_grad():
                    r = self.residual(torch.cat([q, qd, qdd, cmd], -1)).to(self.device)
                if self.kind == "torque":
                    tau = r
                else:
                    target = target + r
            q_new, qd_new = self.sim.step(target, tau)
            qdd = (qd_new - qd) / self.dt
            q, qd = q_new, qd_new
        bad = self.sim.diverged(q, qd, self.limits)
        if bad.any():  # keep NaN out of the policy; the environment ends those episodes
            ids = bad.nonzero().squeeze(-1)
            q, qd, qdd = (torch.where(bad[:, None], self.q, q), torch.where(bad[:, None], torch.zeros_like(qd), qd),
                          torch.where(bad[:, None], torch.zeros_like(qdd), qdd))
            self.sim.set_state(ids, q[ids], qd[ids])
        self.q, self.qd, self._qdd = q, qd, qdd
        return q, qd, bad


def sim_plant(setting: str, robot, num_worlds: int, rate_hz: float, decimation: int, run: str | None = None,
              device: str = "cpu", ground: bool = False, randomization=None) -> SimPlant:
    """The simulator of a training ``setting`` (:data:`SETTINGS`): ``nominal``; ``calibrated`` from a ``wresdyn fit``
    run (``physics.json`` and the torque residual ``policy.pt``; a run of identified physics alone works too);
    ``delta_action`` from a ``wresdyn fit --model network --residual delta_action`` run. ``ground``: ``robot`` has
    a free base and stands on a floor; the corrections fitted on the stand apply unchanged (the same joints and
    links). ``randomization``: domain randomisation around the setting's physics (:class:`SimPlant`)."""
    from pathlib import Path

    if setting not in SETTINGS:
        raise WresdynError(f"unknown training setting {setting!r}; choose from {SETTINGS}")
    if setting == "nominal":
        return SimPlant(robot, num_worlds, rate_hz, decimation, device=device, ground=ground,
                        randomization=randomization)
    if not run:
        raise WresdynError(f"the {setting} setting needs a run folder (wresdyn fit)")
    run = Path(run)
    physics = run_physics(run, robot)
    policy, meta = load_policy(run) if (run / "policy.pt").is_file() else (None, {"kind": None})
    if list(meta.get("joint_names", robot.joint_names)) != list(robot.joint_names):
        raise WresdynError(f"{run}: fitted on joints {meta['joint_names'][:3]}..., not this robot's")
    if meta.get("arch", "mlp") != "mlp":
        raise WresdynError(f"{run}: a {meta['arch']} residual keeps a hidden state per world; skills take an MLP one")
    if abs(float(meta.get("rate_hz", rate_hz)) - rate_hz) > 1e-9:
        raise WresdynError(f"{run}: fitted at {meta['rate_hz']:g} Hz, the skills run at {rate_hz:g} Hz")
    if setting == "calibrated":
        if physics is None:
            raise WresdynError(f"{run}: no physics.json: the calibrated setting needs a hybrid `wresdyn fit` run")
        if policy is not None and meta["kind"] != "torque":
            raise WresdynError(f"{run}: the calibrated robot carries a torque residual, this run a {meta['kind']} one")
    elif physics is not None or policy is None or meta["kind"] != "delta_action":
        raise WresdynError(f"{run}: the delta-action setting needs a delta_action residual on the robot file's physics "
                           "(wresdyn fit --model network --residual delta_action)")
    return SimPlant(robot, num_worlds, rate_hz, decimation, physics=physics, residual=policy,
                    kind=meta["kind"], device=device, ground=ground, randomization=randomization)


class RealPlant:
    """``num_worlds`` copies of the "real" robot, stepped in C threads by ``mujoco.rollout``: on its stand (a fixed
    base) or, for a floating-base ``real``, standing on its floor.

    The command passes the real robot's delay line (its FIFO at the physics substep) and torque limits exactly as in
    :meth:`~wresdyn.data.real_robot.RealRobot.record`; :meth:`step` returns the sensed joint state (the mismatch's
    noise and quantisation, drawn from ``seed``), :attr:`q_true`/:attr:`qd_true` the true one and :attr:`tau` the
    drive torque at every physics substep of the last step [N*m] (N, S, n), :attr:`q_samples`/:attr:`qd_samples` the
    true state at every recording period of it. Each step reads ``real.model`` as it is then: a caller may change its
    fields between steps (a robot that drifts; :attr:`tau` keeps the gains and limits read at construction). On the
    floor :attr:`base_pose` / :attr:`base_twist` are the true base state and :meth:`imu` what its IMU reports (with
    ``imu_noise``). Each step's rollout starts with a cold constraint-solver warm start (its friction solution
    converges within the solver's iterations).

    Args:
        imu_noise: Standard deviations of the IMU's white noise: angular velocity [rad/s] and the measured gravity
            direction [-] (floor only).
    """

    def __init__(self, real, num_worlds: int, decimation: int, seed: int = 0, threads: int | None = None,
                 imu_noise: tuple[float, float] = (0.0, 0.0)) -> None:
        import mujoco
        from mujoco import rollout

        self.real, self.num_worlds, self.decimation = real, int(num_worlds), int(decimation)
        self.robot, self.device = real.robot, torch.device("cpu")
        self.floating = bool(real.floating)
        self.imu_noise = tuple(float(x) for x in imu_noise)
        self._mj, self._rollout = mujoco, rollout
        m = real.model
        self._spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self._nstate = mujoco.mj_stateSize(m, self._spec)
        if threads is None:  # every core this process may use
            threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        self._datas = [mujoco.MjData(m) for _ in range(max(1, min(int(threads), self.num_worlds)))]
        self.n_sub = real.n_sub * self.decimation
        n = self.robot.n_dof
        d = self._datas[0]
        d.qpos[:] = np.arange(1, m.nq + 1)
        d.qvel[:] = -np.arange(1, m.nv + 1)
        s = np.empty(self._nstate)
        mujoco.mj_getState(m, d, s, self._spec)
        self._iq0 = int(np.flatnonzero(s == 1.0)[0])  # qpos in the state vector
        self._iv0 = int(np.flatnonzero(s == -1.0)[0])  # qvel
        self._iq = self._iq0 + (7 if self.floating else 0)  # the joints
        self._iv = self._iv0 + (6 if self.floating else 0)
        self.kp, self.kd = m.actuator_gainprm[:n, 0].copy(), -m.actuator_biasprm[:n, 2].copy()
        self.lim = m.actuator_forcerange[:n].copy()
        self.limited = m.actuator_forcelimited[:n].astype(bool)
        self.state = np.zeros((self.num_worlds, self._nstate))
        self._base_of = None
        """The base pose and twist (float64) of the state they were read from, ``(state, pose, twist)``: an
        environment step reads them four times (pose, twist, and both again for the IMU)."""
        self._fifo = np.zeros((self.num_worlds, real.n_delay, n))
        self.rng = np.random.default_rng(seed)
        self.q_true = np.zeros((self.num_worlds, n))
        self.qd_true = np.zeros((self.num_worlds, n))
        self.tau = np.zeros((self.num_worlds, self.n_sub, n))
        self.q_samples = np.zeros((self.num_worlds, self.decimation, n))
        """True joint positions [rad] at the start of every recording period of the last step (N, decimation, n),
        the first the state the step started from: what a log at the recording rate holds, before the sensors."""
        self.qd_samples = np.zeros_like(self.q_samples)
        """True joint velocities [rad/s] at the same instants (N, decimation, n)."""

    def reset(self, ids, q, qd) -> None:
        """Place worlds ``ids`` at ``q``, ``qd`` [rad, rad/s] (k, n); the delay line holds ``q``."""
        if self.floating:
            raise ValueError(f"{self.robot.source.name}: a robot on the floor is placed with reset_full")
        self._reset(ids, q, qd)

    def reset_full(self, ids, base_pose, base_twist, q, qd) -> None:
        """Place worlds ``ids`` of the robot on the floor: base pose (k, 7), twist (k, 6) in Newton's free-joint
        convention (:mod:`wresdyn.robot.ground`), joints ``q``, ``qd`` (k, n); the delay line holds ``q``."""

        qpos, qvel = free_to_mujoco(self.robot, np.asarray(torch.as_tensor(base_pose).cpu(), np.float64),
                                    np.asarray(torch.as_tensor(base_twist).cpu(), np.float64))
        self._reset(ids, q, qd, qpos, qvel)

    def _reset(self, ids, q, qd, base_qpos=None, base_qvel=None) -> None:
        ids = np.asarray(torch.as_tensor(ids).cpu())
        if len(ids) == 0:
            return
        q, qd = np.asarray(torch.as_tensor(q).cpu(), np.float64), np.asarray(torch.as_tensor(qd).cpu(), np.float64)
        d, n = self._datas[0], self.robot.n_dof
        for i, w in enumerate(ids):
            self._mj.mj_resetData(self.real.model, d)
            if self.floating:
                d.qpos[:7], d.qvel[:6] = base_qpos[i], base_qvel[i]
            d.qpos[-n:], d.qvel[-n:] = q[i], qd[i]
            self._mj.mj_getState(self.real.model, d, self.state[w], self._spec)
        self._base_of = None  # the state changed in place
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

    def _base(self):
        s = self.state
        if self._base_of is None or self._base_of[0] is not s:  # a step replaces the state array
            self._base_of = (s, *free_from_mujoco(self.robot, s[:, self._iq0:self._iq0 + 7],
                                                  s[:, self._iv0:self._iv0 + 6]))
        pose, twist = self._base_of[1:]
        f32 = dict(dtype=torch.float32)
        return torch.as_tensor(pose, **f32), torch.as_tensor(twist, **f32)

    def imu(self) -> tuple[torch.Tensor, torch.Tensor]:
        """What the base IMU reports: angular velocity [rad/s] and the unit gravity direction, both in base axes,
        (N, 3) each, with ``imu_noise``."""

        gyro, grav = base_frame_imu(self.base_pose, self.base_twist)
        sg, sd = self.imu_noise
        if sg > 0:
            gyro = gyro + sg * torch.as_tensor(self.rng.standard_normal(gyro.shape), dtype=torch.float32)
        if sd > 0:
            grav = grav + sd * torch.as_tensor(self.rng.standard_normal(grav.shape), dtype=torch.float32)
            grav = grav / grav.norm(dim=-1, keepdim=True)
        return gyro, grav

    def step(self, cmd) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Hold ``cmd`` [rad] (N, n) for ``decimation`` recording periods; returns the sensed ``(q, qd)`` and
        ``diverged`` (bool (N,), a non-finite state: those worlds are left as before the step)."""
        n = self.robot.n_dof
        cmd = np.asarray(torch.as_tensor(cmd).detach().cpu(), np.float64)
        issued = np.repeat(cmd[:, None], self.n_sub, axis=1)
        line = np.concatenate([self._fifo, issued], axis=1)  # what reaches the motors, oldest first
        ctrl = line[:, :self.n_sub]
        self._fifo = line[:, self.n_sub:]  # the last n_delay commands (none without a delay)
        states, _ = self._rollout.rollout(self.real.model, self._datas, self.state, ctrl, persistent_pool=True)
        prev = np.concatenate([self.state[:, None], states[:, :-1]], axis=1)
        qs, qds = prev[..., self._iq:self._iq + n], prev[..., self._iv:self._iv + n]
        tau = self.kp * (ctrl - qs) - self.kd * qds
        self.tau = np.where(self.limited, np.clip(tau, self.lim[:, 0], self.lim[:, 1]), tau)
        self.q_samples, self.qd_samples = qs[:, ::self.real.n_sub], qds[:, ::self.real.n_sub]
        new = states[:, -1]
        bad = ~np.isfinite(new).all(-1)
        self.state = np.where(bad[:, None], self.state, new)
        self.q_true = self.state[:, self._iq:self._iq + n].copy()
        self.qd_true = self.state[:, self._iv:self._iv + n].copy()
        q, qd = self.real.sense(self.q_true, self.qd_true, self.rng)
        f32 = dict(dtype=torch.float32)
        return torch.as_tensor(q, **f32), torch.as_tensor(qd, **f32), torch.as_tensor(bad)
