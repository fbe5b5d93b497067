"""The configs of the skills, apart from the environment and the learner so that the command line reads them
without importing torch: the tracking task (:class:`SkillTaskConfig`, :mod:`.env`) in its two variants, on the stand
(:class:`SkillConfig`, :meth:`SkillTaskConfig.stand`) and on the floor (:class:`FloorTaskConfig`,
:meth:`SkillTaskConfig.floor`), and the PPO that trains a skill (:class:`SkillPPOConfig`, :mod:`.skill_ppo`).
``wresdyn deploy`` exposes them as ``--task.*`` and ``--ppo.*``.

A variant is a config over the one environment, as mjlab's task variants are: whether the base floats on a floor
(:attr:`SkillTaskConfig.floating`), the reward terms (:attr:`SkillTaskConfig.reward_terms`, one method each in
:class:`~.env.TrackingEnv`, weights here) and the termination rule (a joint's error on the stand, a fall or drift on
the floor) are the config's; the environment, motion library, evaluation and report are shared. Each variant keeps
its own fields, so that the ``task`` record of a run folder lists what that task uses."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..choices import check_number

__all__ = ["SkillTaskConfig", "SkillConfig", "FloorTaskConfig", "SkillPPOConfig"]


@dataclass(frozen=True)
class SkillTaskConfig:
    """The tracking task of a skill: what both variants start with, in their order (the stand's defaults): timing,
    action and the widths of the joint kernels. Each variant adds its own fields after these; :meth:`stand` and
    :meth:`floor` are their defaults.

    Example:
        >>> SkillTaskConfig.floor().floating, SkillTaskConfig.stand(decimation=5).decimation
        (True, 5)
    """

    floating: ClassVar[bool] = False
    """The robot has a free base and stands on a floor (:class:`~.plants.SimPlant` ``ground=True``); the
    environment then reads the base, an IMU and the feet (not a field: the variant's class fixes it)."""
    reward_terms: ClassVar[tuple[str, ...]] = ()
    """The reward terms of the variant, summed in this order (each a method ``_<term>`` of the environment)."""
    name: ClassVar[str] = ""
    """The variant's name: ``stand`` or ``floor``."""

    decimation: int = 10
    """Sample periods per policy step: 10 at 500 Hz is a 50 Hz policy."""
    action_scale: float = 0.2
    """PD-target offset per unit action [rad]."""
    action_clip: float = 3.0
    """Actions are clipped to ±this [-] before scaling."""
    ahead: int = 5
    """The far look-ahead of the observation [policy steps]."""
    sigma_q: float = 0.1
    """Width of the coarse joint-position kernel [rad]."""
    sigma_q_fine: float = 0.03
    """Width of the fine joint-position kernel [rad]."""
    sigma_qd: float = 1.5
    """Width of the joint-velocity kernel [rad/s]."""

    @staticmethod
    def stand(**kw) -> "SkillConfig":
        """The task on the stand (a fixed base), ``kw`` changed."""
        return SkillConfig(**kw)

    @staticmethod
    def floor(**kw) -> "FloorTaskConfig":
        """The task on the floor (a free base keeping its balance), ``kw`` changed."""
        return FloorTaskConfig(**kw)


@dataclass(frozen=True)
class SkillConfig(SkillTaskConfig):
    """The tracking task on the stand: timing, action, rewards and termination (a joint ``fail_error`` from its
    reference)."""

    name: ClassVar[str] = "stand"
    reward_terms: ClassVar[tuple[str, ...]] = ("track_q", "track_q_fine", "track_qd", "action_rate")

    w_q: float = 1.0
    """Weight of the coarse joint-position kernel [-]."""
    w_q_fine: float = 1.0
    """Weight of the fine joint-position kernel [-]."""
    w_qd: float = 0.2
    """Weight of the joint-velocity kernel [-]."""
    w_action_rate: float = 0.05
    """Weight of the mean squared action change per step [-]."""
    fail_error: float = 0.5
    """A joint this far from its reference ends the episode as a failure [rad]."""

    def __post_init__(self) -> None:
        check_number(self.decimation, "skill.decimation", integer=True, ge=1)
        check_number(self.ahead, "skill.ahead", integer=True, ge=1)
        for k in ("action_scale", "action_clip", "sigma_q", "sigma_q_fine", "sigma_qd", "fail_error"):
            check_number(getattr(self, k), f"skill.{k}", gt=0)


@dataclass(frozen=True)
class FloorTaskConfig(SkillTaskConfig):
    """The tracking task on the floor: timing, action, rewards and the fall rule."""

    name: ClassVar[str] = "floor"
    floating: ClassVar[bool] = True
    reward_terms: ClassVar[tuple[str, ...]] = ("track_q", "track_q_fine", "track_qd", "orientation", "base", "slip",
                                               "action_rate", "fall")

    action_scale: float = 0.25
    """PD-target offset per unit action [rad]."""
    sigma_orientation: float = 0.15
    """Width of the base-orientation kernel [rad]."""
    sigma_base: float = 0.1
    """Width of the base-position kernel [m]."""
    w_q: float = 1.0
    """Weight of the coarse joint-position kernel [-]."""
    w_q_fine: float = 0.5
    """Weight of the fine joint-position kernel [-]."""
    w_qd: float = 0.2
    """Weight of the joint-velocity kernel [-]."""
    w_orientation: float = 1.0
    """Weight of the base-orientation kernel [-]."""
    w_base: float = 0.5
    """Weight of the base-position kernel [-]."""
    w_slip: float = 1.0
    """Weight of the mean squared horizontal speed of the planted soles [per (m/s)^2]."""
    w_action_rate: float = 0.05
    """Weight of the mean squared action change per step [-]."""
    w_fall: float = 10.0
    """Penalty on the step an episode fails."""
    fall_height: float = 0.25
    """The base this far below its reference height is a fall [m]."""
    fall_tilt: float = 0.8
    """The base tilted this far from upright is a fall [rad]."""
    max_base_error: float = 0.5
    """The base this far from its reference position ends the episode as a failure [m] (ASAP's success rule)."""
    gyro_noise: float = 0.02
    """The real robot's IMU: white noise on the angular velocity [rad/s]."""
    gravity_noise: float = 0.01
    """... and on the measured gravity direction [-]."""

    def __post_init__(self) -> None:
        check_number(self.decimation, "floor.decimation", integer=True, ge=1)
        check_number(self.ahead, "floor.ahead", integer=True, ge=1)
        for k in ("action_scale", "action_clip", "sigma_q", "sigma_q_fine", "sigma_qd", "sigma_orientation",
                  "sigma_base", "fall_height", "fall_tilt", "max_base_error"):
            check_number(getattr(self, k), f"floor.{k}", gt=0)
        for k in ("gyro_noise", "gravity_noise"):
            check_number(getattr(self, k), f"floor.{k}", ge=0)


@dataclass(frozen=True)
class SkillPPOConfig:
    """PPO of the skills (rsl-rl ``OnPolicyRunner``). The number of worlds is not PPO's: it is the plant's
    ``num_worlds``, which the runner reads as ``env.num_envs``."""

    iterations: int = 300
    """PPO iterations (a resumed run may raise it)."""
    num_steps_per_env: int = 24
    """Policy steps each world collects per iteration."""
    hidden_dims: tuple[int, ...] = (256, 128)
    """Hidden layer widths of the actor and of the critic."""
    init_std: float = 0.3
    """Initial action noise [-] (× action_scale rad)."""
    restart_std: float | None = None
    """Action noise a fine-tuning restarts from [-] (``None``: the initial policy's own). PPO on many worlds shrinks the
    noise far (0.30 -> 0.05 in 300 iterations at 4096 worlds), and a fine-tuning from there barely explores."""
    output_gain: float = 0.01
    """The actor's last layer starts scaled by this: the untrained policy plays the reference (zero action)."""
    learning_rate: float = 1e-3
    """Adam's initial learning rate (then adapted to ``desired_kl``)."""
    gamma: float = 0.97
    """Discount factor per policy step."""
    lam: float = 0.95
    """GAE lambda."""
    entropy_coef: float = 0.002
    """Weight of the entropy bonus."""
    num_learning_epochs: int = 5
    """Passes over each rollout per iteration."""
    num_mini_batches: int = 4
    """Mini-batches per pass."""
    desired_kl: float = 0.01
    """Target KL divergence per update of the adaptive learning rate."""
    save_interval: int = 50
    """Iterations between checkpoints ``model_<it>.pt``."""
    seed: int = 0
    """Seed of torch and numpy's global generator."""
    device: str = "cpu"
    """Torch device of the policy and the update."""
    torch_threads: int | None = 2
    """Torch threads (pinned: an unpinned learner runs many times slower on a loaded machine; ``None``: torch's
    default)."""
    one_sync_update: bool = False
    """The PPO update with one host synchronisation per iteration (:class:`~wresdyn.ppo.update.OneSyncPPO`)
    instead of rsl-rl's several per mini-batch; the same update up to rounding."""

    def __post_init__(self) -> None:
        for k in ("iterations", "num_steps_per_env", "num_learning_epochs", "num_mini_batches",
                  "save_interval"):
            check_number(getattr(self, k), f"ppo.{k}", integer=True, ge=1)
        if self.restart_std is not None:
            check_number(self.restart_std, "ppo.restart_std", gt=0)
        if self.torch_threads is not None:
            check_number(self.torch_threads, "ppo.torch_threads", integer=True, ge=1)
