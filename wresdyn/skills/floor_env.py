"""Motion tracking on the floor: the rsl-rl environment of a humanoid that must keep its balance, on any plant with a
free base (:class:`~wresdyn.skills.plants.SimPlant` ``ground=True``, :class:`~wresdyn.skills.plants.RealPlant` of
a floating real robot).

Each world plays one floor motion (:mod:`wresdyn.skills.floor_motions`) from a random policy step, starting in the
reference state there (joints and base), and its policy sets the PD targets every policy period:

    q_cmd = q_ref(t + 1) + action_scale · clip(a, −action_clip, action_clip).

The actor sees what a humanoid senses without motion capture (:data:`ACTOR_TERMS`): joint states, the base IMU
(angular velocity and the gravity direction in base axes), the reference and its previous action; no base
position or linear velocity. The critic also sees privileged state (:data:`CRITIC_TERMS`: the base's position
error and velocity, the true angular velocity, the reference's planted feet), rsl-rl's asymmetric actor-critic.
Rewards, one method per term with its weight in :class:`FloorTaskConfig`: joint tracking (coarse, fine, velocity),
base orientation and position tracking, foot slip of the soles the reference plants, action rate and a fall
penalty. An episode ends at the motion's end, or fails on a fall: the base more than ``fall_height`` below its
reference or tilted past ``fall_tilt``, or more than ``max_base_error`` from the reference (ASAP's success rule).
"""

from __future__ import annotations

import time
from dataclasses import asdict

import numpy as np
import torch
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from ..sim.kinematics import BodyPositions
from .env import start_points
from .skill_config import FloorTaskConfig

__all__ = ["FloorTaskConfig", "FloorTrackingEnv", "ACTOR_TERMS", "CRITIC_TERMS", "base_frame_imu", "quat_rotate_inv",
           "FOOT_BODIES", "FAILURE_CAUSES"]

ACTOR_TERMS = ("error", "qd", "ref_next", "ref_ahead", "ref", "last_action", "gyro", "gravity")
"""The actor's observation: n values each for the joint terms, 3 each for the IMU's."""
CRITIC_TERMS = ("base_error", "base_velocity", "true_gyro", "planted")
"""What the critic sees besides the actor's observation: 3, 3, 3 and 2 values."""
FAILURE_CAUSES = ("fell_low", "tilted", "drifted", "diverged")
"""Why an episode fails: the base fell below its reference by ``fall_height``, tilted past ``fall_tilt``, drifted
more than ``max_base_error`` from the reference, or the simulation diverged (the first that holds, in this order)."""
FOOT_BODIES = ("left_foot", "right_foot")
"""The bodies whose slip is penalised where the reference plants them."""


def quat_rotate_inv(quat_xyzw: torch.Tensor, v: torch.Tensor) -> torch.Tensor:
    """Rotate world vectors ``v`` (N, 3) into the frame of unit quaternions ``quat_xyzw`` (N, 4)."""
    xyz, w = quat_xyzw[:, :3], quat_xyzw[:, 3:4]
    t = 2.0 * torch.cross(xyz, v, dim=-1)
    return v - w * t + torch.cross(xyz, t, dim=-1)


def base_frame_imu(base_pose: torch.Tensor, base_twist: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """An ideal IMU on the base: angular velocity [rad/s] and the unit gravity direction (z down), in base axes."""
    down = torch.zeros_like(base_pose[:, :3])
    down[:, 2] = -1.0
    quat = base_pose[:, 3:]
    return quat_rotate_inv(quat, base_twist[:, 3:]), quat_rotate_inv(quat, down)


def _angle(qa: torch.Tensor, qb: torch.Tensor) -> torch.Tensor:
    """Rotation angle between unit quaternions (N, 4) [rad]."""
    return 2.0 * torch.acos((qa * qb).sum(-1).abs().clamp(max=1.0))


def _tilt(quat: torch.Tensor) -> torch.Tensor:
    """Angle between the base's up axis and the world's [rad]."""
    x, y = quat[:, 0], quat[:, 1]
    return torch.acos((1.0 - 2.0 * (x * x + y * y)).clamp(-1.0, 1.0))


def floor_reference(motions, decimation: int, ahead: int, device):
    """Motions at the policy rate, padded with their last sample by ``ahead`` steps: joints q (M, W, n) [rad],
    q̇ (M, W, n) [rad/s], base pose (M, W, 7), base displacement per sample period (M, W, 3) [m], planted soles
    (M, W, 2), and the policy steps of each motion (M,)."""
    k = [(len(m.q) - 1) // decimation for m in motions]
    width = max(k) + 1 + ahead
    n = motions[0].q.shape[1]
    out = {"q": np.empty((len(motions), width, n)), "qd": np.zeros((len(motions), width, n)),
           "base": np.empty((len(motions), width, 7)), "base_v": np.zeros((len(motions), width, 3)),
           "planted": np.ones((len(motions), width, 2))}
    for i, m in enumerate(motions):
        sl = slice(None, None, decimation)
        v = np.gradient(m.base[:, :3], axis=0)  # per sample period
        for key, src in (("q", m.q), ("qd", m.qd), ("base", m.base), ("base_v", v), ("planted", m.planted)):
            sub = src[sl][:k[i] + 1]
            out[key][i, :len(sub)] = sub
            if key in ("qd", "base_v"):
                out[key][i, len(sub):] = 0.0
            else:
                out[key][i, len(sub):] = sub[-1]
    f = dict(dtype=torch.float32, device=device)
    ref = {key: torch.as_tensor(v, **f) for key, v in out.items()}
    ref["planted"] = ref["planted"] > 0.5
    return ref, torch.as_tensor(k, dtype=torch.long, device=device)


class FloorTrackingEnv(VecEnv):
    """rsl-rl vectorised environment: every world of a floor ``plant`` tracks one of ``motions``; see the module
    docstring. Observation groups: ``policy`` (the actor's) and ``critic`` (the privileged terms the critic adds).

    Args:
        plant: A plant with a free base on the floor (``reset_full``, ``base_pose``, ``base_twist``); its
            ``decimation`` must equal ``cfg.decimation``. A plant with an ``imu()`` (the real robot) is read through
            it; others through an ideal IMU.
        motions: Floor motions (:class:`~wresdyn.skills.floor_motions.FloorMotion`) at the plant's rate.
        cfg: The task.
        seed: Seed of the motion and start draws.
        random_start: Start at a random policy step (training); ``False``: world i plays motion ``i mod M`` from its
            start once (deployment).
        device: Torch device of the observations, rewards and the policy (default: the plant's).
    """

    critic_groups = ("policy", "critic")
    """What the critic sees (:func:`wresdyn.skills.skill_ppo.train_skill`)."""

    def __init__(self, plant, motions, cfg: FloorTaskConfig = FloorTaskConfig(), seed: int = 0,
                 random_start: bool = True, device=None):
        if plant.decimation != cfg.decimation:
            raise ValueError(f"plant decimation {plant.decimation} != task decimation {cfg.decimation}")
        self.plant, self.cfg, self.motions = plant, cfg, list(motions)
        self.num_envs, self.num_actions = plant.n_worlds, plant.robot.n_dof
        self.device = torch.device(device) if device is not None else plant.device
        self.ref_data, self.ref_len = floor_reference(self.motions, cfg.decimation, cfg.ahead, self.device)
        self.ref_q = self.ref_data["q"]
        self.max_episode_length = int(self.ref_len.max())
        self.random_start = random_start
        self.sample_dt = plant_dt(plant)
        self.policy_dt = cfg.decimation * self.sample_dt
        """Policy period [s]."""
        self.gen = torch.Generator(device=self.device)
        self.gen.manual_seed(seed)
        n, dev, w = self.num_actions, self.device, self.num_envs
        self.fk = BodyPositions(plant.robot, w, str(plant.device) if plant.device.type == "cuda" else "cpu")
        names = list(plant.robot.body_names)
        self.feet = torch.as_tensor([names.index(b) for b in FOOT_BODIES], device=self.fk.device)
        self.motion = torch.zeros(w, dtype=torch.long, device=dev)
        self.t = torch.zeros_like(self.motion)
        """Current policy step in the motion, per world."""
        self.episode_length_buf = torch.zeros_like(self.motion)
        self.q, self.qd = torch.zeros(w, n, device=dev), torch.zeros(w, n, device=dev)
        self.base_pose = torch.zeros(w, 7, device=dev)
        self.base_twist = torch.zeros(w, 6, device=dev)
        self.gyro, self.gravity = torch.zeros(w, 3, device=dev), torch.zeros(w, 3, device=dev)
        self.feet_pos = torch.zeros(w, 2, 3, device=dev)
        self.last_action = torch.zeros(w, n, device=dev)
        self.failed_total = self.diverged_total = self.episodes_total = 0
        self.steps_total, self.step_seconds = 0, 0.0
        self.cfg_dict = asdict(cfg)
        self._reset(torch.arange(w, device=dev))

    # ------------------------------------------------------------------------------------------------ state
    def _read_plant(self, q, qd) -> None:
        p = self.plant
        self.q, self.qd = q.to(self.device), qd.to(self.device)
        self.base_pose, self.base_twist = p.base_pose.to(self.device), p.base_twist.to(self.device)
        if hasattr(p, "imu"):
            gyro, grav = p.imu()
        else:
            gyro, grav = base_frame_imu(self.base_pose, self.base_twist)
        self.gyro, self.gravity = gyro.to(self.device), grav.to(self.device)
        true_q = getattr(p, "q_true", None)
        self.true_q = self.q.clone() if true_q is None else torch.as_tensor(np.array(true_q), dtype=torch.float32,
                                                                            device=self.device)
        """The true joint positions [rad] (N, n): the real robot's, not its sensors'."""
        self.bodies = self.fk(self.base_pose, self.true_q).to(self.device)
        """World positions of every body [m] (N, n_bodies, 3), from the true state."""
        self.feet_pos = self.bodies[:, self.feet]

    def _reset(self, ids: torch.Tensor) -> None:
        if len(ids) == 0:
            return
        k = len(ids)
        m, t = start_points(ids, self.ref_len, self.random_start, self.gen, self.device)
        self.motion[ids], self.t[ids] = m, t
        r = self.ref_data
        twist = torch.zeros(k, 6, device=self.device)
        twist[:, :3] = r["base_v"][m, t] / self.sample_dt
        self.plant.reset_full(ids, r["base"][m, t], twist, r["q"][m, t], r["qd"][m, t])
        self.last_action[ids] = 0.0
        self.episode_length_buf[ids] = 0
        if len(ids) == self.num_envs:
            self._read_plant(r["q"][m, t], r["qd"][m, t])
        else:
            self.q[ids], self.qd[ids] = r["q"][m, t], r["qd"][m, t]
            self.base_pose[ids], self.base_twist[ids] = r["base"][m, t], twist
            gyro, grav = base_frame_imu(self.base_pose[ids], self.base_twist[ids])
            self.gyro[ids], self.gravity[ids] = gyro, grav

    def ref(self, key: str = "q", offset: int = 0) -> torch.Tensor:
        """Reference ``key`` at each world's step + ``offset``."""
        return self.ref_data[key][self.motion, self.t + offset]

    # ------------------------------------------------------------------------------------------------ observations
    def get_observations(self) -> TensorDict:
        r0 = self.ref()
        actor = torch.cat([(self.q - r0) / 0.1, 0.1 * self.qd, (self.ref("q", 1) - r0) / 0.05,
                           (self.ref("q", self.cfg.ahead) - r0) / 0.2, r0, self.last_action, 0.25 * self.gyro,
                           self.gravity], dim=-1)
        quat = self.base_pose[:, 3:]
        critic = torch.cat([(self.base_pose[:, :3] - self.ref("base")[:, :3]) / 0.1,
                            quat_rotate_inv(quat, self.base_twist[:, :3]),
                            0.25 * quat_rotate_inv(quat, self.base_twist[:, 3:]),
                            self.ref("planted").float()], dim=-1)
        return TensorDict({"policy": actor, "critic": critic}, batch_size=[self.num_envs], device=self.device)

    # ------------------------------------------------------------------------------------------------ rewards
    def _track_q(self, e2):
        return self.cfg.w_q * torch.exp(-e2 / self.cfg.sigma_q ** 2)

    def _track_q_fine(self, e2):
        return self.cfg.w_q_fine * torch.exp(-e2 / self.cfg.sigma_q_fine ** 2)

    def _track_qd(self, v2):
        return self.cfg.w_qd * torch.exp(-v2 / self.cfg.sigma_qd ** 2)

    def _orientation(self, ang):
        return self.cfg.w_orientation * torch.exp(-(ang / self.cfg.sigma_orientation) ** 2)

    def _base(self, dist):
        return self.cfg.w_base * torch.exp(-(dist / self.cfg.sigma_base) ** 2)

    def _slip(self, speed2):
        return -self.cfg.w_slip * speed2

    def _action_rate(self, a):
        return -self.cfg.w_action_rate * ((a - self.last_action) ** 2).mean(-1)

    def _fall(self, failed):
        return -self.cfg.w_fall * failed.float()

    # ------------------------------------------------------------------------------------------------ step
    def command(self, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """The clipped action (N, n) and the PD target it sets [rad] (N, n)."""
        a = actions.to(self.device).clamp(-self.cfg.action_clip, self.cfg.action_clip)
        return a, self.ref("q", 1) + self.cfg.action_scale * a

    def step(self, actions: torch.Tensor):
        t0 = time.perf_counter()
        c = self.cfg
        a, cmd = self.command(actions)
        self.cmd = cmd
        """The PD targets of the last step [rad] (N, n)."""
        feet_before = self.feet_pos
        q, qd, bad = self.plant.step(cmd)
        bad = bad.to(self.device)
        self._read_plant(q, qd)
        self.t += 1
        self.episode_length_buf += 1
        q_r, qd_r, base_r = self.ref(), self.ref("qd"), self.ref("base")
        e2, v2 = ((self.q - q_r) ** 2).mean(-1), ((self.qd - qd_r) ** 2).mean(-1)
        ang = _angle(self.base_pose[:, 3:], base_r[:, 3:])
        dist = (self.base_pose[:, :3] - base_r[:, :3]).norm(dim=-1)
        planted = self.ref("planted") & self.ref("planted", -1)
        slide = ((self.feet_pos - feet_before)[..., :2].norm(dim=-1) / self.policy_dt) ** 2
        slip2 = (slide * planted).sum(-1) / planted.sum(-1).clamp(min=1)
        fell = ((self.base_pose[:, 2] < base_r[:, 2] - c.fall_height) | (_tilt(self.base_pose[:, 3:]) > c.fall_tilt)
                | ~torch.isfinite(self.base_pose).all(-1))
        drifted = dist > c.max_base_error
        failed = fell | drifted | bad
        # why a world failed, first cause first: 0 none, then the indices of FAILURE_CAUSES
        cause = torch.zeros_like(self.t)
        for code, hit in ((4, bad), (3, drifted), (2, _tilt(self.base_pose[:, 3:]) > c.fall_tilt),
                          (1, self.base_pose[:, 2] < base_r[:, 2] - c.fall_height)):
            cause = torch.where(hit, torch.full_like(cause, code), cause)
        self.failure_cause = cause
        """Why each world failed this step (N,): 0 it did not, else 1 + the index in :data:`FAILURE_CAUSES`."""
        terms = {"track_q": self._track_q(e2), "track_q_fine": self._track_q_fine(e2), "track_qd": self._track_qd(v2),
                 "orientation": self._orientation(ang), "base": self._base(dist), "slip": self._slip(slip2),
                 "action_rate": self._action_rate(a), "fall": self._fall(failed)}
        reward = torch.nan_to_num(torch.stack(list(terms.values())).sum(0), nan=0.0)
        time_out = (self.t >= self.ref_len[self.motion]) & ~failed
        dones = failed | time_out
        self.last_action = a
        self.fell, self.slip2, self.base_error, self.orientation_error = fell, slip2, dist, ang
        log = {f"Reward/{k}": v.mean() for k, v in terms.items()}
        log["Error/mpjpe"] = (self.q - q_r).abs().mean()
        log["Env/fell"] = fell.float().sum()
        self.failed_total += int(failed.sum())
        self.diverged_total += int(bad.sum())
        self.episodes_total += int(dones.sum())
        self.step_base_pose = self.base_pose.clone()
        """The base pose after this step, before any reset (N, 7): deployment metrics."""
        self.step_true_q = self.true_q.clone()
        self.step_bodies = self.bodies.clone()
        self._reset(dones.nonzero().squeeze(-1))
        self.steps_total += self.num_envs
        self.step_seconds += time.perf_counter() - t0
        return self.get_observations(), reward, dones.long(), {"time_outs": time_out, "log": log}


def plant_dt(plant) -> float:
    """The sample period of a plant [s]."""
    dt = getattr(plant, "dt", None)
    if dt is not None:
        return float(dt)
    return 1.0 / float(plant.real.rate_hz)
