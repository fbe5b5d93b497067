"""The configuration of a residual-learning run (:func:`wresdyn.ppo.trainer.train`).

:class:`TrainConfig` gathers the replay environment, the residual, the Table I rewards and the PPO settings; its nested
fields change by their dotted names through :mod:`wresdyn.config_fields`. This module imports neither torch nor
rsl-rl itself: the command line reads its fields without building a learner.
"""

from __future__ import annotations

from dataclasses import MISSING, dataclass, field, fields, is_dataclass

from ..choices import check_device, check_number
from ..errors import WresdynError
from ..learn.residual_config import ResidualConfig
from ..learn.runs import read_unset
from .replay_env_config import ReplayEnvConfig, RewardConfig

__all__ = ["PPOConfig", "COMPILE_MODES", "TrainConfig", "RESUME_MAY_CHANGE", "DATASET_IDENTITY", "RENAMED",
           "default_config", "config_from_dict", "upgrade_config_dict"]


COMPILE_MODES = ("", "default", "max-autotune-no-cudagraphs")
"""``PPOConfig.compile_mode`` values: off, or the ``torch.compile`` modes rsl-rl accepts."""


@dataclass(frozen=True)
class PPOConfig:
    """PPO and runner settings (rsl-rl ``PPO`` / ``OnPolicyRunner``). The number of worlds is the environment's
    (``env.num_worlds``), which the runner reads as ``env.num_envs``."""

    num_steps_per_env: int = 24
    """Rollout length per world per iteration [steps]."""
    iterations: int = 4000
    """Total PPO iterations of the run (a resumed run continues up to this number). 4000 (24.6 M env-steps,
    about 35 min on 2 CPU cores with the replay solver) cut the shipped benchmark's held-out error 3.17x
    (seed 1: 2.996x); the training error flattens after about 2500."""
    save_interval: int = 50
    """Checkpoint every this many iterations."""
    learning_rate: float = 1e-3
    """Initial Adam step size (adapted to ``desired_kl``)."""
    num_learning_epochs: int = 5
    """Passes over each rollout."""
    num_mini_batches: int = 4
    """Mini-batches per pass."""
    gamma: float = 0.9
    """Discount per step; 1/(1−γ) = 10 steps = 20 ms at 500 Hz, about the PD time constants: a residual's
    effect on tracking shows within that window, and a longer one only adds variance. Chosen by the sweep in
    ``benchmarks/results/h200_ppo_sweep``, which scored on the held-out split: not yet checked on validation."""
    lam: float = 0.9
    """GAE λ."""
    clip_param: float = 0.2
    """PPO ratio clip."""
    entropy_coef: float = 0.0
    """Entropy bonus; zero so the exploration noise can shrink to the precision the residual needs."""
    value_loss_coef: float = 1.0
    """Value loss weight."""
    desired_kl: float = 0.03
    """Target KL for the adaptive learning rate; 0.01 (rsl-rl's default) halved the progress per iteration
    on the shipped benchmark (1.3x vs 1.8x held-out after 500 iterations), 0.08 was no better than 0.03."""
    max_grad_norm: float = 1.0
    """Gradient clip."""
    seed: int = 0
    """Seed of torch and of the episode sampler."""
    device: str = "cpu"
    """Simulation and learning device (``cpu``, ``cuda:0``)."""
    torch_threads: int | None = 1
    """CPU threads for torch (``None``: torch's default). One is fastest for these small batches: on a busy 2-core
    machine two intra-op threads made a (256, 84) gather-and-normalise 600x slower (20 ms vs 31 us)."""
    select_every: int | None = None
    """Replay the validation split open loop every this many iterations and export the residual with the lowest
    validation error (model selection on validation); ``None`` = ten times per run."""
    cuda_graph: bool = True
    """On CUDA, replay each environment step from a CUDA graph (:class:`~wresdyn.ppo.replay_env.ReplayEnv`); the
    runner's per-step NaN check (a host sync) is then off: the environment keeps non-finite states out of what it
    returns (diverged worlds are reset and counted)."""
    one_sync_update: bool = False
    """Run the PPO update with one host synchronisation per iteration (:class:`~wresdyn.ppo.update.OneSyncPPO`:
    the adaptive learning rate on the device, gradients and KL in one all-reduce per mini-batch across processes)
    instead of rsl-rl's ~5 per mini-batch; the same update up to rounding."""
    graph_update: bool | None = None
    """On CUDA, replay each mini-batch's whole update step (forward, backward, the all-reduce, clip, Adam) from one
    CUDA graph (:class:`~wresdyn.ppo.graph_update.GraphPPO`), so the host launches one graph per mini-batch instead
    of its kernels one by one. The packed update up to Adam's rounding (capturable Adam); on the CPU, with mixed
    precision or with ``compile_mode`` the packed update runs as without it, bit for bit. ``None`` (the default):
    this update unless ``one_sync_update`` asks for that one; ``True`` refuses ``one_sync_update``; ``False``: the
    packed update everywhere. On by default on CUDA because two H200s ran it: its four CUDA tests passed (one GPU,
    two over NCCL), an iteration took 2.2-2.7x less than the packed update's and two GPUs kept 89-94 % of twice one
    (``benchmarks/results/speed/h200x2_20261130f/ppo90g``). The skills' PPO
    (:class:`~wresdyn.skills.skill_config.SkillPPOConfig`) has no such switch and keeps rsl-rl's update: no test
    covers a captured update of its networks."""
    mixed_precision: bool = False
    """rsl-rl's mixed precision: the update's forward passes and losses under bfloat16 autocast."""
    compile_mode: str = ""
    """rsl-rl's ``torch.compile`` of the actor and critic: ``""`` (off), ``"default"`` or
    ``"max-autotune-no-cudagraphs"`` (rsl-rl refuses the CUDA-graph modes)."""

    pin_cpus: bool = False
    """Bind each training process to the CPU cores local to its GPU (:func:`wresdyn.ppo.affinity.pin_process`:
    sysfs's ``local_cpulist``, split among the ranks that share it; else an even split of the allowed cores by local
    rank). Off: the scheduler places the processes."""
    deferred_episode_log: bool | None = None
    """Keep rsl-rl's episode reward and length bookkeeping on the device and copy it to the host once per iteration
    (:func:`wresdyn.ppo.episode_log.defer_episode_log`) instead of a host wait at every rollout step on the logging
    rank; the same logged numbers and the same learning bit for bit (``tests/ppo/test_episode_log.py``, one process
    and two). ``None`` (the default): on where ``device`` is CUDA, off on the CPU (:meth:`defers_episode_log`), so
    every CPU run stays bit for bit what it was; ``True``/``False`` force it. On by default on CUDA because the
    rounds of ``benchmarks/results/speed/h200x2_20261130h`` and ``h200x4_20261130i`` ran faster with it in every
    round on 1, 2 and 4 H200s (one GPU of the latter: 1.45-1.50M -> 1.66-1.72M env-steps/s); nothing measured it on
    the CPU, where the demo and CI run."""

    def __post_init__(self) -> None:
        for name in ("num_steps_per_env", "iterations", "save_interval", "num_learning_epochs",
                     "num_mini_batches"):
            check_number(getattr(self, name), f"ppo.{name}", integer=True, ge=1)
        for name in ("learning_rate", "clip_param", "desired_kl", "max_grad_norm"):
            check_number(getattr(self, name), f"ppo.{name}", gt=0)
        for name in ("entropy_coef", "value_loss_coef"):
            check_number(getattr(self, name), f"ppo.{name}", ge=0)
        check_number(self.gamma, "ppo.gamma", gt=0, le=1)
        check_number(self.lam, "ppo.lam", ge=0, le=1)
        check_number(self.seed, "ppo.seed", integer=True, ge=0, le=2**32 - 1)  # numpy's seed range
        for name in ("torch_threads", "select_every"):
            if getattr(self, name) is not None:
                check_number(getattr(self, name), f"ppo.{name}", integer=True, ge=1)
        check_device(self.device, "ppo.device")
        if self.graph_update is True and self.one_sync_update:
            raise WresdynError("ppo.graph_update and ppo.one_sync_update are two updates; choose one")
        if self.compile_mode not in COMPILE_MODES:
            raise WresdynError(f"ppo.compile_mode = {self.compile_mode!r}; choose from {COMPILE_MODES}")

    def defers_episode_log(self) -> bool:
        """Whether the run keeps its episode bookkeeping on the device (``deferred_episode_log`` with ``None``
        resolved by ``device``: on for ``cuda`` and ``cuda:N``, off for ``cpu``)."""
        if self.deferred_episode_log is not None:
            return self.deferred_episode_log
        return self.device.startswith("cuda")


RESUME_MAY_CHANGE = ("iterations", "device", "save_interval", "torch_threads", "cuda_graph", "one_sync_update",
                     "graph_update", "mixed_precision", "compile_mode", "pin_cpus", "deferred_episode_log")
""":class:`PPOConfig` fields a resumed run may change: how long, where and how it runs (the arithmetic of the
update included, as a change of device changes it), not what it learns."""

DATASET_IDENTITY = ("train", "joint_names", "rate_hz")
"""What of the data in ``config.json`` a resumed run must share: the training trajectories (by name), the joints
and the sample rate. The dataset's path may change (a run moved to another machine)."""


@dataclass(frozen=True)
class TrainConfig:
    """Everything a residual-learning run depends on besides the data."""

    env: ReplayEnvConfig = field(default_factory=ReplayEnvConfig)
    """Replay environment."""
    residual: ResidualConfig = field(default_factory=ResidualConfig)
    """Residual kind and network."""
    rewards: RewardConfig = field(default_factory=RewardConfig)
    """Table I weights and widths."""
    ppo: PPOConfig = field(default_factory=PPOConfig)
    """PPO and runner."""

    def __post_init__(self) -> None:
        for name, cls in (("env", ReplayEnvConfig), ("residual", ResidualConfig), ("rewards", RewardConfig),
                          ("ppo", PPOConfig)):
            value = getattr(self, name)
            if not isinstance(value, cls):
                raise TypeError(f"TrainConfig.{name} must be a {cls.__name__}, not {type(value).__name__}")
        # rsl-rl splits a rollout into mini-batches by world for a recurrent policy, by sample otherwise, and
        # an empty mini-batch fails deep inside the update
        p, worlds = self.ppo, self.env.num_worlds
        per_batch = worlds if self.residual.arch == "gru" else worlds * p.num_steps_per_env
        if p.num_mini_batches > per_batch:
            unit = "worlds (a GRU is batched by world)" if self.residual.arch == "gru" else "samples per rollout"
            raise WresdynError(f"ppo.num_mini_batches = {p.num_mini_batches} is more than the {per_batch} {unit}")


def default_config() -> TrainConfig:
    """The default task: torque residual, MLP, Table I rewards, sized for a 2-core CPU demo run."""
    return TrainConfig()


RENAMED = {"ppo.num_envs": "env.num_worlds"}
"""Dotted names a :class:`TrainConfig` field is still read by (a run folder's ``config.json``, ``--set``), and the
field each names: the world count is the environment's."""


def renamed(item: str) -> str:
    """A ``SECTION.FIELD=VALUE`` item (``--set``) with a name of :data:`RENAMED` written as the field's own."""
    key, sep, text = str(item).partition("=")
    return RENAMED.get(key.strip(), key.strip()) + sep + text if sep else item


def upgrade_config_dict(d: dict) -> dict:
    """An ``asdict`` of :class:`TrainConfig` with each field of :data:`RENAMED` moved to its name (a dict that has
    them under their names is returned as it is)."""
    d = {k: dict(v) if isinstance(v, dict) else v for k, v in d.items()}
    for old, new in RENAMED.items():
        (s_old, f_old), (s_new, f_new) = old.split("."), new.split(".")
        if isinstance(d.get(s_old), dict) and f_old in d[s_old]:
            value = d[s_old].pop(f_old)
            d.setdefault(s_new, {}).setdefault(f_new, value)
    return d


def config_from_dict(d: dict) -> TrainConfig:
    """Inverse of ``dataclasses.asdict`` for :class:`TrainConfig` (lists back to tuples; a run folder's legacy 0 for
    "unset" as ``None``, :func:`~wresdyn.learn.runs.read_unset`; the names of :data:`RENAMED` as their fields)."""

    def build(cls, values):
        kw = {}
        for f in fields(cls):
            if f.name not in values:
                continue
            v = values[f.name]
            sub = f.default_factory() if f.default_factory is not MISSING else None  # type: ignore[misc]
            if is_dataclass(sub):
                v = build(type(sub), v)
            elif isinstance(v, list):
                v = tuple(v)
            kw[f.name] = v
        return cls(**kw)

    return build(TrainConfig, read_unset(upgrade_config_dict(d)))
