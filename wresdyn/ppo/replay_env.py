"""Replay environment: N Newton worlds follow recorded joint commands under PD plus a learned residual.

Each world starts at a random time of a random training trajectory, in the recorded state there, and
runs the recorded ``q_cmd`` open-loop through the simulated PD drives plus the residual (torque into
``control.joint_f`` or offset on ``control.joint_target_q``, see :mod:`wresdyn.learn.residual`). At every step
the simulated state is compared with the recording at the same time index (Table I rewards). A world
that diverges (non-finite state, runaway velocity, far past a joint limit, or far from the recording)
is reset and counted; its state never reaches the learner.

:class:`ReplayEnv` is the rsl-rl ``VecEnv`` on the simulation layer: :class:`wresdyn.sim.Simulator` steps the
worlds, :class:`wresdyn.sim.TrajectoryBank` holds the recordings (and the command path's delay),
:func:`wresdyn.sim.residual_kinds.apply_residual` applies the residual and :meth:`wresdyn.sim.Simulator.diverged`
judges divergence, as for every other consumer of the replay.
"""

from __future__ import annotations

import time
from dataclasses import asdict

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from ..learn.residual import ResidualConfig, obs_stats
from ..sim import DivergenceLimits, Simulator, TrajectoryBank
from ..sim.bank import servo_goal_accel
from ..sim.residual_kinds import apply_residual, observation, residual_scale
from .replay_env_config import ReplayEnvConfig
from .rewards import TERMS, RewardConfig, reward_terms

__all__ = ["ReplayEnvConfig", "ReplayEnv"]


class ReplayEnv(VecEnv):
    """rsl-rl vectorised environment replaying recorded trajectories; see the module docstring.

    Observation groups: ``policy`` = normalised [q, q̇, q̈, q_cmd] (N, 4n); ``critic`` adds the privileged
    tracking error (q − q_r, q̇ − q̇_r, scaled) and the fraction of the episode left, (N, 6n + 1).
    Actions a (N, n) become the residual clip(g · a, −1, 1) · :func:`~wresdyn.sim.residual_kinds.residual_scale`, g the
    configured ``action_gain``; the action terms of the reward see a clipped to ±1/g.

    A step never waits on the device: diverged worlds are masked, not branched on, and resets draw a start for
    every world and keep it where the episode ended. On CUDA (``graph=True``) the whole step (residual, solver,
    divergence, rewards, resets, observations) is captured once per starting state buffer as a CUDA graph (torch's
    capture on the simulator's stream, Warp's launches joining it as an external capture) and replayed; the CPU runs
    the same code eagerly.

    ``physics``: the :class:`~wresdyn.sim.physics.PhysicalParams` the worlds simulate (the hybrid's identified
    ones, their delay on the commands), or ``None``: the robot file's values, no delay.
    """

    def __init__(self, robot, trajectories, rate_hz: float, num_worlds: int, cfg: ReplayEnvConfig = ReplayEnvConfig(),
                 residual: ResidualConfig = ResidualConfig(), rewards: RewardConfig = RewardConfig(),
                 device: str | None = "cpu", seed: int = 0, obs_mean=None, obs_std=None, graph: bool = True,
                 weights=None, physics=None) -> None:
        self.robot, self.env_cfg, self.residual_cfg, self.reward_cfg = robot, cfg, residual, rewards
        self.dt = 1.0 / rate_hz
        self.sim = Simulator(robot, num_worlds, self.dt, solver=cfg.solver, substeps=cfg.substeps, device=device,
                             friction_kappa=cfg.friction_kappa)
        self.limits = DivergenceLimits(cfg.max_qd, cfg.limit_margin, cfg.max_error)
        self.device = self.sim.device
        self.num_actions = robot.n_dof
        self.max_episode_length = cfg.horizon
        self.cfg = {"env": asdict(cfg), "residual": asdict(residual), "rewards": asdict(rewards), "rate_hz": rate_hz}
        self.physics = physics
        """The physical parameters the worlds simulate (the hybrid's identified ones), or ``None``: the robot file's."""
        delay = 0.0
        if physics is not None:
            self.sim.set_physics(physics)
            delay = torch.as_tensor(physics.delay * rate_hz, dtype=torch.float32, device=self.device)
        self.bank = TrajectoryBank(trajectories, self.device, delay,
                                   servo_goal_accel(robot, physics, 1.0 / rate_hz, self.device))
        if obs_mean is None or obs_std is None:
            obs_mean, obs_std = obs_stats(trajectories)
        dev, f32 = self.device, torch.float32

        def t(x):
            return torch.as_tensor(np.asarray(x), dtype=f32, device=dev)

        self.obs_mean, self.obs_std = t(obs_mean), t(obs_std)
        self.scale = t(residual_scale(robot, residual.kind, residual.fraction))
        gains = self.physics if self.physics is not None else robot
        self.kp, self.kd = t(gains.kp), t(gains.kd)
        self.weights = None if weights is None or (np.asarray(weights) > 0).all() else t(weights)
        """Per-joint weights (n,) of the tracking rewards and errors, 0 for joints the dataset excludes from fitting
        (:meth:`~wresdyn.data.dataset.Dataset.fit_weights`); ``None`` when every joint is fitted."""
        self.gen = torch.Generator(device=dev)
        self.gen.manual_seed(seed)
        n, z = robot.n_dof, torch.zeros
        # every piece of episode state below is updated in place, so a captured step (CUDA graph) reads and writes
        # the same memory as an eager one
        self.q, self.qd, self.qdd = (z(num_worlds, n, device=dev) for _ in range(3))
        self.a1, self.a2 = z(num_worlds, n, device=dev), z(num_worlds, n, device=dev)
        """Network actions at t−1 and t−2, clipped as in :meth:`step`."""
        self.g = torch.zeros(num_worlds, dtype=torch.long, device=dev)
        """Current row in the trajectory bank, per world."""
        self.end = torch.zeros_like(self.g)
        """Last row of the current episode, per world."""
        self.episode_length_buf = torch.zeros_like(self.g)
        self._diverged = torch.zeros((), dtype=torch.long, device=dev)
        self.steps_total, self.step_seconds = 0, 0.0
        """World-steps taken and wall time spent in :meth:`step` since construction [s] (throughput; with a CUDA
        graph the host time of the launches, the GPU's share shows in the runner's collection time)."""
        # episode starts: trajectory j is drawn with weight (span_j + 1), the number of starts it offers
        self._span = (self.bank.length - 1 - self.max_episode_length).clamp(min=0)
        self._cdf = torch.cumsum((self._span + 1).float(), 0)
        self.graph = self.sim.graph and bool(graph)
        """Replay :meth:`step` from CUDA graphs (on CUDA unless ``graph=False``): one launch per step, no host sync."""
        self._graphs: dict[int, tuple] = {}
        self._warm: set[int] = set()
        self._act_in = z(num_worlds, n, device=dev)
        self.reset_all(random_length=True)

    @property
    def num_worlds(self) -> int:
        """Parallel worlds: the simulator's ``num_worlds`` (the simulator owns the count; nothing else stores it)."""
        return self.sim.num_worlds

    @property
    def num_envs(self) -> int:
        """:attr:`num_worlds` under the name rsl-rl's ``VecEnv`` reads."""
        return self.sim.num_worlds

    @property
    def diverged_total(self) -> int:
        """Worlds reset for runaway since construction (reads the device counter: a sync on CUDA)."""
        return int(self._diverged)

    # -- episodes -------------------------------------------------------------------------------------------

    def reset_all(self, random_length: bool = False) -> None:
        """Restart every world; with ``random_length`` the first episodes end at staggered times."""
        self._reset_masked(torch.ones(self.num_envs, dtype=torch.bool, device=self.device), random_length,
                           self.gen)

    def _reset(self, ids: torch.Tensor, random_length: bool = False) -> None:
        """Restart worlds ``ids`` (long (k,))."""
        mask = torch.zeros(self.num_envs, dtype=torch.bool, device=self.device)
        mask[ids] = True
        self._reset_masked(mask, random_length, self.gen)

    def _reset_masked(self, mask: torch.Tensor, random_length: bool, gen) -> None:
        """Restart the worlds where ``mask`` (N,) bool: a new start drawn for every world, kept where ``mask``
        (no host sync and fixed shapes, so it runs inside a CUDA graph)."""
        bank, n = self.bank, self.num_envs
        u = torch.rand(3 if random_length else 2, n, device=self.device, generator=gen)
        # trajectory by inverse CDF of its weight, then a uniform start among those it offers
        traj = torch.searchsorted(self._cdf, u[0] * self._cdf[-1], right=True).clamp(max=len(self._cdf) - 1)
        s = (u[1] * (self._span[traj] + 1)).long()
        steps = torch.minimum(bank.length[traj] - 1 - s, torch.full_like(s, self.max_episode_length))
        if random_length:
            steps = 1 + (u[2] * steps).long()
        g = bank.start[traj] + s
        m = mask[:, None]
        self.g.copy_(torch.where(mask, g, self.g))
        self.end.copy_(torch.where(mask, g + steps, self.end))
        self.q.copy_(torch.where(m, bank.q[g], self.q))
        self.qd.copy_(torch.where(m, bank.qd[g], self.qd))
        self.qdd.copy_(torch.where(m, bank.qdd[g], self.qdd))
        self.a1.masked_fill_(m, 0.0)
        self.a2.masked_fill_(m, 0.0)
        self.episode_length_buf.masked_fill_(mask, 0)
        self.sim.set_state_where(mask, self.q, self.qd)

    # -- VecEnv -------------------------------------------------------------------------------------------

    def get_observations(self) -> TensorDict:
        policy, critic = self._observations(self.gen)
        return TensorDict({"policy": policy, "critic": critic}, batch_size=[self.num_envs], device=self.device)

    def _observations(self, gen) -> tuple[torch.Tensor, torch.Tensor]:
        bank, g = self.bank, self.g
        clean = (observation(self.q, self.qd, self.qdd, bank.q_cmd[g]) - self.obs_mean) / self.obs_std
        policy = clean
        if self.env_cfg.obs_noise > 0.0:
            policy = clean + self.env_cfg.obs_noise * torch.randn(clean.shape, device=self.device, generator=gen)
        left = ((self.end - g).float() / self.max_episode_length).unsqueeze(-1)
        critic = torch.cat([clean, (self.q - bank.q[g]) / self.env_cfg.critic_err_scale_q,
                            (self.qd - bank.qd[g]) / self.env_cfg.critic_err_scale_qd, left], dim=-1)
        return policy, critic

    LOG_KEYS = tuple(f"Reward/{k}" for k in TERMS) + ("Reward/mimic", "Error/mean_abs_dq", "Error/mean_abs_dqd",
                                                      "Env/diverged")
    """What :meth:`step` logs (``extras["log"]``), in the order of the log vector."""

    def _step(self, actions: torch.Tensor, gen) -> tuple[torch.Tensor, ...]:
        """One step on the device, no host sync: (policy obs, critic obs, reward, dones, time_outs, log vector)."""
        limit = 1.0 / self.residual_cfg.action_gain
        a = actions.clamp(-limit, limit)
        res = a * (self.residual_cfg.action_gain * self.scale)
        target, tau_res = apply_residual(self.bank.target(self.g), res, self.residual_cfg.kind)
        q0, qd0 = self.q, self.qd
        # joint torque at the start of the step, PD plus residual (Table I torque term); a solver that
        # clamps the drive or treats kd implicitly applies slightly less
        tau = self.kp * (target - q0) - self.kd * qd0
        if tau_res is not None:
            tau = tau + tau_res
        q, qd = self.sim.step(target, tau_res)
        qdd = (qd - qd0) / self.dt
        self.g += 1
        self.episode_length_buf += 1
        q_r, qd_r = self.bank.q[self.g], self.bank.qd[self.g]
        bad = self.sim.diverged(q, qd, self.limits, q_r)
        # keep NaN and runaway values out of the reward and the observation
        b = bad[:, None]
        q, qd, qdd = torch.where(b, q_r, q), torch.where(b, qd_r, qd), torch.where(b, self.bank.qdd[self.g], qdd)
        self._diverged += bad.sum()
        terms = reward_terms(self.reward_cfg, q, qd, qdd, q_r, qd_r, tau, a, self.a1, self.a2, weights=self.weights)
        reward = torch.stack(list(terms.values())).sum(0)
        reward = torch.where(bad, torch.zeros_like(reward), reward)
        time_out = (self.g >= self.end) & ~bad
        dones = bad | time_out
        self.q.copy_(q)
        self.qd.copy_(qd)
        self.qdd.copy_(qdd)
        self.a2.copy_(self.a1)
        self.a1.copy_(a)
        means = torch.stack([v.mean() for v in terms.values()])
        w = self.weights  # excluded joints out of the logged errors too (a weighted mean: no host sync)
        dq, dqd = (q - q_r).abs(), (qd - qd_r).abs()
        if w is None:
            err = torch.stack([dq.mean(), dqd.mean()])
        else:
            err = torch.stack([(dq * w).sum(-1).mean(), (dqd * w).sum(-1).mean()]) / w.sum()
        log = torch.cat([means, (means[0] + means[1])[None], err, bad.float().sum()[None]])
        self._reset_masked(dones, False, gen)
        policy, critic = self._observations(gen)
        return policy, critic, reward, dones.long(), time_out, log

    def _step_graphed(self, actions: torch.Tensor) -> tuple[torch.Tensor, ...]:
        """:meth:`_step` replayed from a CUDA graph captured per starting state buffer (the simulator's states
        ping-pong); the first step from each buffer runs eagerly to load kernels and warm torch up. Outputs are
        cloned: the graph's own buffers are overwritten by the next replay."""
        import warp as wp

        sim = self.sim
        start = sim._cur
        if start not in self._warm:  # eager, on the simulator's stream as the capture will be
            self._warm.add(start)
            # after torch's current stream: the actions and the episode state were written there
            sim.side_stream().wait_stream(torch.cuda.current_stream(self.device))
            with torch.cuda.stream(sim.side_stream()):
                out = self._step(actions, None)
            torch.cuda.current_stream(self.device).wait_stream(sim.side_stream())
            return out
        entry = self._graphs.get(start)
        if entry is None:
            graph = torch.cuda.CUDAGraph()
            s = sim.side_stream()
            s.wait_stream(torch.cuda.current_stream(self.device))
            sim.graph = False  # the solver's own graph would nest; its launches go into this one
            try:
                with torch.cuda.graph(graph, stream=s, capture_error_mode="thread_local"):
                    wp.capture_begin(stream=sim._wp_side, external=True, capture_mode=wp.CaptureMode.THREAD_LOCAL)
                    try:
                        outputs = self._step(self._act_in, None)
                    finally:
                        wp.capture_end(stream=sim._wp_side)
            finally:
                sim.graph = True
            entry = self._graphs[start] = (graph, outputs, sim._cur)
            sim._cur = start
        graph, outputs, after = entry
        self._act_in.copy_(actions)
        graph.replay()
        sim._cur = after
        return tuple(o.clone() for o in outputs)

    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        t0 = time.perf_counter()
        actions = actions.to(self.device)
        if self.graph:
            policy, critic, reward, dones, time_out, log = self._step_graphed(actions)
        else:
            policy, critic, reward, dones, time_out, log = self._step(actions, self.gen)
        obs = TensorDict({"policy": policy, "critic": critic}, batch_size=[self.num_envs], device=self.device)
        extras = {"time_outs": time_out, "log": dict(zip(self.LOG_KEYS, log.unbind()))}
        self.steps_total += self.num_envs
        self.step_seconds += time.perf_counter() - t0
        return obs, reward, dones, extras
