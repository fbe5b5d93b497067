"""Motion tracking: the one rsl-rl environment of the skills, on any plant (:mod:`wresdyn.skills.plants`), its task
config (:class:`~.skill_config.SkillTaskConfig`) choosing the variant: on the stand or on the floor.

Each world plays one reference motion (:mod:`wresdyn.skills.motions`) from a random policy step, starting in the
reference state there (reference state initialisation; on the floor the base's too), and its policy sets the PD
targets every policy period:

    q_cmd = q_ref(t + 1) + action_scale · clip(a, −action_clip, action_clip),

so a zero action plays the reference open loop through the PD drives (the policy learns the correction). The
policy observes proprioception and the motion (:data:`OBS_TERMS`): the tracking error q − q_ref(t), q̇, the
reference's next steps q_ref(t + 1) − q_ref(t) and q_ref(t + 5) − q_ref(t), q_ref(t) itself and its previous action.
On the floor it also observes what a humanoid senses without motion capture (:data:`IMU_TERMS`: the base's angular
velocity and the gravity direction in base axes), no base position or linear velocity, while the critic sees
privileged state (:data:`CRITIC_TERMS`: the base's position error and velocity, the true angular velocity, the
reference's planted feet), rsl-rl's asymmetric actor-critic.

Rewards, one method per term of the task's :attr:`~.skill_config.SkillTaskConfig.reward_terms`, weights in the
config: exponential kernels on joint position (coarse and fine) and velocity, minus an action-rate penalty; on the
floor also base orientation and position kernels, the slip of the soles the reference plants and a fall penalty.
An episode ends at the motion's end (a time-out) or fails: on the stand a joint more than ``fail_error`` from its
reference or a plant that runs away; on the floor a fall (the base more than ``fall_height`` below its reference or
tilted past ``fall_tilt``), the base more than ``max_base_error`` from the reference (ASAP's success rule) or a
runaway (:data:`FAILURE_CAUSES`). In training a drift ends the episode as a fall does (the episode is lost either
way); in deployment (``drift_ends=False``, :func:`wresdyn.skills.evaluate.deploy`) a drifted world plays on, so that
a topple that follows it is seen and counted as the fall it is.
"""

from __future__ import annotations

import time
from dataclasses import asdict

import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from ..sim.kinematics import BodyPositions
from .feasibility import FOOT_BODIES
from .reference import base_frame_imu, motion_tensors, plant_dt, quat_angle, quat_rotate_inv, start_points, tilt
from .skill_config import FloorTaskConfig, SkillConfig, SkillTaskConfig

__all__ = ["SkillTaskConfig", "SkillConfig", "FloorTaskConfig", "TrackingEnv", "OBS_TERMS", "IMU_TERMS",
           "CRITIC_TERMS", "FOOT_BODIES", "FAILURE_CAUSES", "FALLS"]

OBS_TERMS = ("error", "qd", "ref_next", "ref_ahead", "ref", "last_action")
"""The policy's observation, n values each, in this order."""
IMU_TERMS = ("gyro", "gravity")
"""What the policy also observes on the floor, after :data:`OBS_TERMS`: 3 values each."""
CRITIC_TERMS = ("base_error", "base_velocity", "true_gyro", "planted")
"""What the critic sees on the floor besides the actor's observation: 3, 3, 3 and 2 values."""
FAILURE_CAUSES = ("fell_low", "tilted", "drifted", "diverged")
"""Why an episode on the floor fails: the base fell below its reference by ``fall_height``, tilted past
``fall_tilt``, drifted more than ``max_base_error`` from the reference, or the simulation diverged. The first two are
falls; a step that sees several causes reports the first in this order (a topple that also drifts is a fall)."""
FALLS = FAILURE_CAUSES[:2]
"""The causes that are falls."""


class TrackingEnv(VecEnv):
    """rsl-rl vectorised environment: every world of ``plant`` tracks one of ``motions``; see the module docstring.
    Observation groups: ``policy`` (the actor's) and, on the floor, ``critic`` (the privileged terms it adds).

    Args:
        plant: A :class:`~wresdyn.skills.plants.SimPlant` or :class:`~wresdyn.skills.plants.RealPlant`; its
            ``decimation`` must equal ``cfg.decimation``. On the floor it has a free base (``reset_full``,
            ``base_pose``, ``base_twist``); one with an ``imu()`` (the real robot) is read through it, others through
            an ideal IMU.
        motions: Reference motions (:class:`~wresdyn.skills.motions.Motion`) at the plant's rate (on the floor,
            with their base).
        cfg: The task: :meth:`SkillTaskConfig.stand` or :meth:`SkillTaskConfig.floor`.
        seed: Seed of the motion and start draws.
        random_start: Start at a random policy step (training); ``False``: every world plays motion
            ``i mod M`` from its start once (deployment, :mod:`wresdyn.skills.evaluate`).
        device: Torch device of the observations, rewards and the policy (default: the plant's). The real robot
            steps on CPU threads while its policy may learn on a GPU.
        drift_ends: On the floor, a base more than ``max_base_error`` from the reference ends the episode
            (training); ``False``: the world plays on (deployment watches it for a fall), :attr:`drifted` says so.

    Example:
        >>> env = TrackingEnv(SimPlant(robot, 4, 500.0, 10), motions.split("train"), SkillTaskConfig.stand())
        >>> obs, reward, dones, extras = env.step(torch.zeros(env.num_envs, env.num_actions))
    """

    def __init__(self, plant, motions, cfg: SkillTaskConfig = SkillConfig(), seed: int = 0, random_start: bool = True,
                 device=None, drift_ends: bool = True):
        if plant.decimation != cfg.decimation:
            raise ValueError(f"plant decimation {plant.decimation} != task decimation {cfg.decimation}")
        self.plant, self.cfg, self.motions = plant, cfg, list(motions)
        self.floating = cfg.floating
        self.num_actions = plant.robot.n_dof
        self.device = torch.device(device) if device is not None else plant.device
        self.ref_data, self.ref_len = motion_tensors(self.motions, cfg.decimation, cfg.ahead, self.device)
        self.ref_q, self.ref_qd = self.ref_data["q"], self.ref_data["qd"]
        self.max_episode_length = int(self.ref_len.max())
        self.random_start, self.drift_ends = random_start, drift_ends
        self.critic_groups = ("policy", "critic") if self.floating else ("policy",)
        """What the critic sees (:func:`wresdyn.skills.skill_ppo.train_skill`)."""
        self.gen = torch.Generator(device=self.device)
        self.gen.manual_seed(seed)
        n, dev, w = self.num_actions, self.device, self.num_envs
        self.motion = torch.zeros(w, dtype=torch.long, device=dev)
        self.t = torch.zeros_like(self.motion)
        """Current policy step in the motion, per world."""
        self.episode_length_buf = torch.zeros_like(self.motion)
        self.q, self.qd = torch.zeros(w, n, device=dev), torch.zeros(w, n, device=dev)
        self.last_action = torch.zeros(w, n, device=dev)
        if self.floating:
            self.sample_dt = plant_dt(plant)
            self.policy_dt = cfg.decimation * self.sample_dt
            """Policy period [s] (floor)."""
            self.fk = BodyPositions(plant.robot, w, str(plant.device) if plant.device.type == "cuda" else "cpu")
            names = list(plant.robot.body_names)
            self.feet = torch.as_tensor([names.index(b) for b in FOOT_BODIES], device=self.fk.device)
            self.base_pose, self.base_twist = torch.zeros(w, 7, device=dev), torch.zeros(w, 6, device=dev)
            self.gyro, self.gravity = torch.zeros(w, 3, device=dev), torch.zeros(w, 3, device=dev)
            self.feet_pos = torch.zeros(w, 2, 3, device=dev)
        self.failed_total = self.diverged_total = self.episodes_total = 0
        self.steps_total, self.step_seconds = 0, 0.0
        self.cfg_dict = asdict(cfg)
        self._reset(torch.arange(w, device=dev))

    @property
    def num_envs(self) -> int:
        """Parallel worlds: the plant's ``num_worlds``, under the name rsl-rl's ``VecEnv`` reads (the plant owns the
        count; nothing else stores it)."""
        return self.plant.num_worlds

    # ------------------------------------------------------------------------------------------------ state
    def _true_q(self) -> torch.Tensor:
        """The true joint positions [rad] (N, n): the real robot's (not its sensors'), else the plant's."""
        true = getattr(self.plant, "q_true", None)  # numpy (MuJoCo C) or a tensor on the plant's device (mujoco_warp)
        return self.q.clone() if true is None else torch.as_tensor(true).to(self.device, torch.float32, copy=True)

    def _read_plant(self, q, qd) -> None:
        """Take the plant's state after a step or a full reset: joints and, on the floor, base, IMU and feet."""
        self.q, self.qd = q.to(self.device), qd.to(self.device)
        if not self.floating:
            return
        p = self.plant
        self.base_pose, self.base_twist = p.base_pose.to(self.device), p.base_twist.to(self.device)
        if hasattr(p, "imu"):
            gyro, grav = p.imu()
        else:
            gyro, grav = base_frame_imu(self.base_pose, self.base_twist)
        self.gyro, self.gravity = gyro.to(self.device), grav.to(self.device)
        self.true_q = self._true_q()
        """The true joint positions [rad] (N, n): the real robot's, not its sensors'."""
        self.bodies = self.fk(self.base_pose, self.true_q).to(self.device)
        """World positions of every body [m] (N, n_bodies, 3), from the true state (floor)."""
        self.feet_pos = self.bodies[:, self.feet]

    def _reset(self, ids: torch.Tensor) -> None:
        if len(ids) == 0:
            return
        m, t = start_points(ids, self.ref_len, self.random_start, self.gen, self.device)
        self.motion[ids], self.t[ids] = m, t
        r = self.ref_data
        q0, qd0 = r["q"][m, t], r["qd"][m, t]
        if not self.floating:
            self.plant.reset(ids, q0, qd0)
            self.q[ids], self.qd[ids] = q0, qd0
            self.last_action[ids] = 0.0
            self.episode_length_buf[ids] = 0
            return
        twist = torch.zeros(len(ids), 6, device=self.device)
        twist[:, :3] = r["base_v"][m, t] / self.sample_dt
        self.plant.reset_full(ids, r["base"][m, t], twist, q0, qd0)
        self.last_action[ids] = 0.0
        self.episode_length_buf[ids] = 0
        if len(ids) == self.num_envs:
            self._read_plant(q0, qd0)
        else:
            self.q[ids], self.qd[ids] = q0, qd0
            self.base_pose[ids], self.base_twist[ids] = r["base"][m, t], twist
            gyro, grav = base_frame_imu(self.base_pose[ids], self.base_twist[ids])
            self.gyro[ids], self.gravity[ids] = gyro, grav

    def ref(self, offset: int = 0, key: str = "q") -> torch.Tensor:
        """Reference ``key`` (joint positions [rad] (N, n) by default) at each world's step + ``offset``."""
        return self.ref_data[key][self.motion, self.t + offset]

    # ------------------------------------------------------------------------------------------------ observations
    def get_observations(self) -> TensorDict:
        r0 = self.ref()
        terms = [(self.q - r0) / 0.1, 0.1 * self.qd, (self.ref(1) - r0) / 0.05, (self.ref(self.cfg.ahead) - r0) / 0.2,
                 r0, self.last_action]
        if not self.floating:
            return TensorDict({"policy": torch.cat(terms, dim=-1)}, batch_size=[self.num_envs], device=self.device)
        actor = torch.cat(terms + [0.25 * self.gyro, self.gravity], dim=-1)
        quat = self.base_pose[:, 3:]
        critic = torch.cat([(self.base_pose[:, :3] - self.ref(key="base")[:, :3]) / 0.1,
                            quat_rotate_inv(quat, self.base_twist[:, :3]),
                            0.25 * quat_rotate_inv(quat, self.base_twist[:, 3:]),
                            self.ref(key="planted").float()], dim=-1)
        return TensorDict({"policy": actor, "critic": critic}, batch_size=[self.num_envs], device=self.device)

    # ------------------------------------------------------------------------------------------------ rewards
    # one method per term of cfg.reward_terms, of the step's errors x; weights and widths in the config
    def _track_q(self, x):
        return self.cfg.w_q * torch.exp(-x["e2"] / self.cfg.sigma_q ** 2)

    def _track_q_fine(self, x):
        return self.cfg.w_q_fine * torch.exp(-x["e2"] / self.cfg.sigma_q_fine ** 2)

    def _track_qd(self, x):
        return self.cfg.w_qd * torch.exp(-x["v2"] / self.cfg.sigma_qd ** 2)

    def _orientation(self, x):
        return self.cfg.w_orientation * torch.exp(-(x["ang"] / self.cfg.sigma_orientation) ** 2)

    def _base(self, x):
        return self.cfg.w_base * torch.exp(-(x["dist"] / self.cfg.sigma_base) ** 2)

    def _slip(self, x):
        return -self.cfg.w_slip * x["slip2"]

    def _action_rate(self, x):
        return -self.cfg.w_action_rate * ((x["a"] - self.last_action) ** 2).mean(-1)

    def _fall(self, x):
        return -self.cfg.w_fall * x["failed"].float()

    # ------------------------------------------------------------------------------------------------ step
    def command(self, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The clipped action (N, n) and the PD target it sets [rad] (N, n)."""
        a = actions.to(self.device).clamp(-self.cfg.action_clip, self.cfg.action_clip)
        return a, self.ref(1) + self.cfg.action_scale * a

    def _floor_failures(self, x: dict, bad: torch.Tensor, feet_before: torch.Tensor) -> torch.Tensor:
        """The base's errors, the soles' slip and the falls of a step on the floor, into ``x``; which worlds failed."""
        c, base_r = self.cfg, self.ref(key="base")
        x["ang"] = quat_angle(self.base_pose[:, 3:], base_r[:, 3:])
        x["dist"] = (self.base_pose[:, :3] - base_r[:, :3]).norm(dim=-1)
        planted = self.ref(key="planted") & self.ref(-1, "planted")
        slide = ((self.feet_pos - feet_before)[..., :2].norm(dim=-1) / self.policy_dt) ** 2
        x["slip2"] = (slide * planted).sum(-1) / planted.sum(-1).clamp(min=1)
        low = self.base_pose[:, 2] < base_r[:, 2] - c.fall_height
        tilted = tilt(self.base_pose[:, 3:]) > c.fall_tilt
        fell = low | tilted | ~torch.isfinite(self.base_pose).all(-1)
        drifted = x["dist"] > c.max_base_error
        # why a world failed, first cause first (a fall before a drift, both before a runaway): 0 none, then
        # 1 + the index in FAILURE_CAUSES
        cause = torch.zeros_like(self.t)
        for code, hit in ((4, bad), (3, drifted), (2, tilted), (1, low)):
            cause = torch.where(hit, torch.full_like(cause, code), cause)
        self.failure_cause = cause
        """Why each world failed this step (N,): 0 it did not, else 1 + the index in :data:`FAILURE_CAUSES`."""
        self.fell, self.slip2, self.base_error, self.orientation_error = fell, x["slip2"], x["dist"], x["ang"]
        self.drifted = drifted
        """The base is more than ``max_base_error`` from the reference after this step (N,) bool (floor)."""
        return fell | bad | (drifted if self.drift_ends else torch.zeros_like(drifted))

    def step(self, actions: torch.Tensor):
        t0 = time.perf_counter()
        a, cmd = self.command(actions)
        self.cmd = cmd
        """The PD targets of the last step [rad] (N, n)."""
        feet_before = self.feet_pos if self.floating else None
        q, qd, bad = self.plant.step(cmd)
        bad = bad.to(self.device)
        self._read_plant(q, qd)
        self.t += 1
        self.episode_length_buf += 1
        q_r, qd_r = self.ref(), self.ref(key="qd")
        x = {"e2": ((self.q - q_r) ** 2).mean(-1), "v2": ((self.qd - qd_r) ** 2).mean(-1), "a": a}
        if self.floating:
            failed = self._floor_failures(x, bad, feet_before)
        else:
            failed = ((self.q - q_r).abs().max(-1).values > self.cfg.fail_error) | bad
        x["failed"] = failed
        terms = {k: getattr(self, f"_{k}")(x) for k in self.cfg.reward_terms}
        reward = torch.stack(list(terms.values())).sum(0)
        # a runaway world on the stand earns nothing; on the floor the fall term charges it
        if self.floating:
            reward = torch.nan_to_num(reward, nan=0.0)
        else:
            reward = torch.where(bad, torch.zeros_like(reward), reward)
        time_out = (self.t >= self.ref_len[self.motion]) & ~failed
        dones = failed | time_out
        self.last_action = a
        log = {f"Reward/{k}": v.mean() for k, v in terms.items()}
        log["Error/mpjpe"] = (self.q - q_r).abs().mean()
        if self.floating:
            log["Env/fell"] = self.fell.float().sum()
        else:
            log["Env/failed"] = failed.float().sum()
        self.failed_total += int(failed.sum())
        self.diverged_total += int(bad.sum())
        self.episodes_total += int(dones.sum())
        if not self.floating:
            self.true_q = self._true_q()
        self.step_true_q = self.true_q.clone()
        """The true joint positions after this step, before any reset [rad] (N, n): the real robot's, not its
        sensors' (deployment metrics)."""
        if self.floating:
            self.step_base_pose = self.base_pose.clone()
            """The base pose after this step, before any reset (N, 7) (floor)."""
            self.step_bodies = self.bodies.clone()
        self._reset(dones.nonzero().squeeze(-1))
        self.steps_total += self.num_envs
        self.step_seconds += time.perf_counter() - t0
        return self.get_observations(), reward, dones.long(), {"time_outs": time_out, "log": log}
