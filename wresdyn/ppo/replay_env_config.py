"""The replay environment's episodes (:class:`ReplayEnvConfig`) and Table I reward weights (:class:`RewardConfig`),
apart from :mod:`.replay_env` and :mod:`.rewards` so that the command line reads them without importing torch."""

from __future__ import annotations

from dataclasses import dataclass, fields

from ..choices import SolverKind, check_choice, check_friction_kappa, check_number
from ..errors import WresdynError

__all__ = ["ReplayEnvConfig", "RewardConfig"]


@dataclass(frozen=True)
class ReplayEnvConfig:
    """Episode and simulation settings of the replay environment."""

    num_worlds: int = 256
    """Parallel replay worlds (Newton's word, ``ModelBuilder.replicate``): the environment owns the count and PPO reads
    it from there (rsl-rl's ``env.num_envs``); split evenly over the processes under torchrun."""
    horizon: int = 250
    """Episode length [steps] (shorter when the trajectory ends first)."""
    substeps: int = 1
    """Simulator steps per recorded sample; the sim step is 1 / (rate_hz · substeps) [s]."""
    solver: SolverKind = "auto"
    """Newton solver kind (:data:`wresdyn.sim.SOLVERS`); "auto" takes :class:`wresdyn.sim.solver_replay.SolverReplay`
    for a fixed base: 100-200k env-steps/s with 256 worlds on 2 busy CPU cores against ~1k for
    ``SolverFeatherstone``, with the same PD-only gap on the shipped benchmark (0.0801 vs 0.0798 rad held-out)."""
    friction_kappa: float | None = None
    """Dry-friction law of the replay solver: ``None`` = the soft default (MuJoCo's ``frictionloss``, which creeps at
    τ / (948 m0) below its bound), a number = the damper law of that rate kappa [1/s] (creep τ / (kappa H_ii); ``inf``:
    hard Coulomb friction, exact sticking); see :class:`wresdyn.sim.solver_replay.SolverReplay`. Replay solver only."""
    max_qd: float = 100.0
    """Runaway joint speed [rad/s]: a world past it is reset."""
    limit_margin: float = 0.5
    """Runaway distance beyond a joint limit [rad]."""
    max_error: float = 1.0
    """Runaway distance from the recording, max over joints [rad]."""
    obs_noise: float = 0.0
    """Gaussian noise on the policy's (normalised) observation [normalising stds], a regulariser as in the
    gradient fit (:attr:`wresdyn.fit.gradfit.GradFitConfig.obs_noise`); the critic and the simulation see the
    clean state. 0 = off."""
    physics: str = ""
    """Physical parameters of the simulator (``physics.json`` of ``wresdyn identify``): the residual is learned on
    top of the identified model (the hybrid), whose command delay then is ``physics.delay``. "" = the robot
    file's values, no delay. The command line reads the file; :func:`~wresdyn.ppo.trainer.train` takes the parameters
    themselves (``physics``) and this records where they came from."""
    critic_err_scale_q: float = 0.05
    """Scale of q − q_r in the critic's privileged observation [rad]."""
    critic_err_scale_qd: float = 0.5
    """Scale of q̇ − q̇_r in the critic's privileged observation [rad/s]."""

    def __post_init__(self) -> None:
        check_choice(self.solver, SolverKind, "env.solver")
        check_friction_kappa(self.friction_kappa, "env.friction_kappa", self.solver)
        check_number(self.num_worlds, "env.num_worlds", integer=True, ge=1)
        check_number(self.horizon, "env.horizon", integer=True, ge=1)
        check_number(self.substeps, "env.substeps", integer=True, ge=1)
        check_number(self.obs_noise, "env.obs_noise", ge=0)
        for name in ("max_qd", "limit_margin", "critic_err_scale_q", "critic_err_scale_qd"):
            check_number(getattr(self, name), f"env.{name}", gt=0)
        if not (isinstance(self.max_error, (int, float)) and self.max_error > 0):  # inf: no check
            raise WresdynError(f"env.max_error = {self.max_error!r} must be > 0")


@dataclass(frozen=True)
class RewardConfig:
    """Weights and kernel widths of the reward terms (Table I)."""

    joint_pos_mimic: float = 5.0
    """Weight of φ(q − q_r)."""
    joint_vel_mimic: float = 3.0
    """Weight of φ(q̇ − q̇_r)."""
    joint_pos_bonus: float = 10.0
    """Weight of the fraction of joints within ``bonus_tol`` of the recording."""
    joint_torque: float = -0.5e-5
    """Weight of |τ|² [1/(N*m)²]; τ is the total joint torque, PD plus residual."""
    joint_vel: float = -0.5e-3
    """Weight of |q̇|² [1/(rad/s)²]."""
    joint_acc: float = -0.5e-6
    """Weight of |q̈|² [1/(rad/s²)²]."""
    action_rate: float = -0.5e-4
    """Weight of |a_t − a_{t−1}|² on the normalised actions."""
    action_acc: float = -0.5e-6
    """Weight of |a_t − 2a_{t−1} + a_{t−2}|² on the normalised actions."""
    sigma_q: float = 0.1
    """Width σ of the position mimic kernel [rad²]: φ = e^{-1} at |q − q_r|² = σ, 0.07 rad rms per joint
    over 21 joints, the PD-only gap of the shipped benchmark in training episodes, so φ still has slope
    there (σ = 0.01 gives φ ≈ e^{-24}: no signal) and keeps it down to a few mrad."""
    sigma_qd: float = 10.0
    """Width σ of the velocity mimic kernel [(rad/s)²]: e^{-1} at 0.7 rad/s rms per joint, as ``sigma_q``."""
    bonus_tol: float = 1e-3
    """Joint position bonus tolerance [rad]."""

    def __post_init__(self) -> None:
        for f in fields(self):
            check_number(getattr(self, f.name), f"rewards.{f.name}")  # weights may have either sign
        # a zero width divides by zero in the kernel; a negative one turns φ into a growing exponential
        check_number(self.sigma_q, "rewards.sigma_q", gt=0)
        check_number(self.sigma_qd, "rewards.sigma_qd", gt=0)
        check_number(self.bonus_tol, "rewards.bonus_tol", ge=0)
