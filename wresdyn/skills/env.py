"""Motion tracking on the stand: the rsl-rl environment of the skills, on any plant (:mod:`wresdyn.skills.plants`).

Each world plays one reference motion (:mod:`wresdyn.skills.motions`) from a random policy step, starting in the
reference state there (reference state initialisation), and its policy sets the PD targets every policy period:

    q_cmd = q_ref(t + 1) + action_scale · clip(a, −action_clip, action_clip),

so a zero action plays the reference open loop through the PD drives (the policy learns the correction). The
policy observes proprioception and the motion: the tracking error q − q_ref(t), q̇, the reference's next steps
q_ref(t + 1) − q_ref(t) and q_ref(t + 5) − q_ref(t), q_ref(t) itself and its previous action (:data:`OBS_TERMS`).
Rewards are exponential tracking kernels on joint position (coarse and fine) and velocity, minus an action-rate
penalty (:class:`SkillConfig`). An episode ends at the motion's end (a time-out) or when a joint is more than
``fail_error`` from its reference (a failure), or when the plant runs away.
"""

from __future__ import annotations

import time
from dataclasses import asdict

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from .skill_config import SkillConfig

__all__ = ["SkillConfig", "TrackingEnv", "OBS_TERMS", "reference_tensors", "start_points"]

OBS_TERMS = ("error", "qd", "ref_next", "ref_ahead", "ref", "last_action")
"""The policy's observation, n values each, in this order."""


def reference_tensors(motions, decimation: int, ahead: int, device) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Motions at the policy rate, padded with their last sample by ``ahead`` steps: q_ref [rad] and q̇_ref [rad/s]
    (M, K + ahead, n), and the policy steps of each motion (M,) long."""
    k = [(len(m.q) - 1) // decimation for m in motions]
    width = max(k) + 1 + ahead
    q = np.empty((len(motions), width, motions[0].q.shape[1]))
    qd = np.zeros_like(q)
    for i, m in enumerate(motions):
        sub = m.q[::decimation][:k[i] + 1]
        q[i, :len(sub)], q[i, len(sub):] = sub, sub[-1]
        qd[i, :len(sub)] = m.qd[::decimation][:k[i] + 1]
    f = dict(dtype=torch.float32, device=device)
    return torch.as_tensor(q, **f), torch.as_tensor(qd, **f), torch.as_tensor(k, dtype=torch.long, device=device)


def start_points(ids: torch.Tensor, ref_len: torch.Tensor, random_start: bool, gen: torch.Generator, device
                 ) -> tuple[torch.Tensor, torch.Tensor]:
    """Motion and policy step each reset world of ``ids`` starts from: drawn at random (``random_start``, from
    ``gen`` on ``device``: a motion, then a step below its length ``ref_len``) or in turn, each motion from its
    start."""
    if random_start:
        m = torch.randint(len(ref_len), (len(ids),), generator=gen, device=device)
        t = (torch.rand(len(ids), generator=gen, device=device) * ref_len[m]).long()
    else:
        m, t = ids % len(ref_len), torch.zeros_like(ids)
    return m, t


class TrackingEnv(VecEnv):
    """rsl-rl vectorised environment: every world of ``plant`` tracks one of ``motions``; see the module docstring.

    Args:
        plant: A :class:`~wresdyn.skills.plants.SimPlant` or :class:`~wresdyn.skills.plants.RealPlant`; its
            ``decimation`` must equal ``cfg.decimation``.
        motions: Reference motions (:class:`~wresdyn.skills.motions.Motion`), sampled at the plant's rate.
        cfg: The task.
        seed: Seed of the motion and start draws.
        random_start: Start at a random policy step (training); ``False``: every world plays motion
            ``i mod M`` from its start once (evaluation, :mod:`wresdyn.skills.deploy`).
        device: Torch device of the observations, rewards and the policy (default: the plant's). The real robot
            steps on CPU threads while its policy may learn on a GPU.
    """

    def __init__(self, plant, motions, cfg: SkillConfig = SkillConfig(), seed: int = 0, random_start: bool = True,
                 device=None):
        if plant.decimation != cfg.decimation:
            raise ValueError(f"plant decimation {plant.decimation} != task decimation {cfg.decimation}")
        self.plant, self.cfg, self.motions = plant, cfg, list(motions)
        self.num_envs, self.num_actions = plant.n_worlds, plant.robot.n_dof
        self.device = torch.device(device) if device is not None else plant.device
        self.ref_q, self.ref_qd, self.ref_len = reference_tensors(self.motions, cfg.decimation, cfg.ahead, self.device)
        self.max_episode_length = int(self.ref_len.max())
        self.random_start = random_start
        self.gen = torch.Generator(device=self.device)
        self.gen.manual_seed(seed)
        n, dev = self.num_actions, self.device
        self.motion = torch.zeros(self.num_envs, dtype=torch.long, device=dev)
        self.t = torch.zeros_like(self.motion)
        """Current policy step in the motion, per world."""
        self.episode_length_buf = torch.zeros_like(self.motion)
        self.q, self.qd = torch.zeros(self.num_envs, n, device=dev), torch.zeros(self.num_envs, n, device=dev)
        self.last_action = torch.zeros(self.num_envs, n, device=dev)
        self.failed_total = self.diverged_total = self.episodes_total = 0
        self.steps_total, self.step_seconds = 0, 0.0
        self.cfg_dict = asdict(cfg)
        self._reset(torch.arange(self.num_envs, device=dev))

    def _reset(self, ids: torch.Tensor) -> None:
        if len(ids) == 0:
            return
        m, t = start_points(ids, self.ref_len, self.random_start, self.gen, self.device)
        self.motion[ids], self.t[ids] = m, t
        q0, qd0 = self.ref_q[m, t], self.ref_qd[m, t]
        self.plant.reset(ids, q0, qd0)
        self.q[ids], self.qd[ids] = q0, qd0
        self.last_action[ids] = 0.0
        self.episode_length_buf[ids] = 0

    def ref(self, offset: int = 0) -> torch.Tensor:
        """Reference joint positions at each world's step + ``offset`` [rad] (N, n)."""
        return self.ref_q[self.motion, self.t + offset]

    def get_observations(self) -> TensorDict:
        r0 = self.ref()
        obs = torch.cat([(self.q - r0) / 0.1, 0.1 * self.qd, (self.ref(1) - r0) / 0.05,
                         (self.ref(self.cfg.ahead) - r0) / 0.2, r0, self.last_action], dim=-1)
        return TensorDict({"policy": obs}, batch_size=[self.num_envs], device=self.device)

    def command(self, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The clipped action (N, n) and the PD target it sets [rad] (N, n)."""
        a = actions.to(self.device).clamp(-self.cfg.action_clip, self.cfg.action_clip)
        return a, self.ref(1) + self.cfg.action_scale * a

    def step(self, actions: torch.Tensor):
        t0 = time.perf_counter()
        c = self.cfg
        a, cmd = self.command(actions)
        self.cmd = cmd
        """The PD targets of the last step [rad] (N, n)."""
        q, qd, bad = self.plant.step(cmd)
        q, qd, bad = q.to(self.device), qd.to(self.device), bad.to(self.device)
        self.t += 1
        self.episode_length_buf += 1
        q_r, qd_r = self.ref(), self.ref_qd[self.motion, self.t]
        e2, v2 = ((q - q_r) ** 2).mean(-1), ((qd - qd_r) ** 2).mean(-1)
        terms = {"track_q": c.w_q * torch.exp(-e2 / c.sigma_q ** 2),
                 "track_q_fine": c.w_q_fine * torch.exp(-e2 / c.sigma_q_fine ** 2),
                 "track_qd": c.w_qd * torch.exp(-v2 / c.sigma_qd ** 2),
                 "action_rate": -c.w_action_rate * ((a - self.last_action) ** 2).mean(-1)}
        reward = torch.stack(list(terms.values())).sum(0)
        failed = ((q - q_r).abs().max(-1).values > c.fail_error) | bad
        reward = torch.where(bad, torch.zeros_like(reward), reward)
        time_out = (self.t >= self.ref_len[self.motion]) & ~failed
        dones = failed | time_out
        self.q, self.qd, self.last_action = q, qd, a
        log = {f"Reward/{k}": v.mean() for k, v in terms.items()}
        log["Error/mpjpe"] = (q - q_r).abs().mean()
        log["Env/failed"] = failed.float().sum()
        self.failed_total += int(failed.sum())
        self.diverged_total += int(bad.sum())
        self.episodes_total += int(dones.sum())
        true = getattr(self.plant, "q_true", None)
        self.true_q = q.clone() if true is None else torch.as_tensor(np.array(true), dtype=torch.float32,
                                                                      device=self.device)
        """The true joint positions after this step, before any reset [rad] (N, n): the real robot's, not its
        sensors' (deployment metrics)."""
        self._reset(dones.nonzero().squeeze(-1))
        self.steps_total += self.num_envs
        self.step_seconds += time.perf_counter() - t0
        return self.get_observations(), reward, dones.long(), {"time_outs": time_out, "log": log}
