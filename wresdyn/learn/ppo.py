"""PPO for the residual (paper Sec. II-B) through rsl-rl's ``OnPolicyRunner``.

A run folder holds everything: ``config.json`` (the :class:`TrainConfig`), rsl-rl checkpoints
``model_<it>.pt`` (resumed from automatically after a kill), tensorboard event files, ``best.pt`` (the actor
with the lowest validation error so far and the validation curve), and at the end the deterministic residual
exported through ``torch.export`` (``policy.pt``, :mod:`wresdyn.export.program`) and ONNX (``policy.onnx``) with its metadata (``residual.json``), plus
``train_summary.json`` (env-steps/s, s per iteration, the selected iteration) and ``train.log``: rsl-rl's networks
and per-iteration tables (kept off the terminal, where a progress bar stands per iteration, :func:`on_iteration`)
and, from ``wresdyn train``, every line the command printed.

Model selection is made on the dataset's validation split: every ``ppo.select_every`` iterations the current
residual replays the validation trajectories open loop (:class:`wresdyn.learn.selection.ValidationScore`), and
the residual with the lowest error is the one exported. Held-out and OOD data are never read in training.

A resume is refused, naming the fields, when the configuration or the training data differ from what the folder
was started with (:data:`RESUME_MAY_CHANGE` may differ), and checkpoints are read as weights only (:class:`Runner`).
"""

from __future__ import annotations

import json
import re
import time
from dataclasses import MISSING, asdict, dataclass, field, fields, is_dataclass
from pathlib import Path

import numpy as np
from rsl_rl.runners import OnPolicyRunner

from ..choices import check_device, check_number
from ..errors import WresdynError
from .replay_env import ReplayEnvConfig
from .residual import ResidualConfig
from .rewards import RewardConfig
from .runs import RunError, check_resume, load_checkpoint, save_checkpoint

__all__ = ["PPOConfig", "TrainConfig", "Ranks", "default_config", "config_from_dict", "parse_overrides", "apply_overrides",
           "set_fields", "set_field", "runner_cfg", "Runner", "on_iteration", "train", "latest_checkpoint", "load_policy", "RunError",
           "RESUME_MAY_CHANGE", "DATASET_IDENTITY"]


@dataclass(frozen=True)
class PPOConfig:
    """PPO and runner settings (rsl-rl ``PPO`` / ``OnPolicyRunner``)."""

    num_envs: int = 256
    """Parallel replay worlds."""
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
    torch_threads: int = 1
    """CPU threads for torch (0: torch's default). One is fastest for these small batches: on a busy 2-core
    machine two intra-op threads made a (256, 84) gather-and-normalise 600x slower (20 ms vs 31 us)."""
    select_every: int = 0
    """Replay the validation split open loop every this many iterations and export the residual with the lowest
    validation error (model selection on validation); 0 = ten times per run."""
    cuda_graph: bool = True
    """On CUDA, replay each environment step from a CUDA graph (:class:`~wresdyn.learn.replay_env.ReplayEnv`); the
    runner's per-step NaN check (a host sync) is then off: the environment keeps non-finite states out of what it
    returns (diverged worlds are reset and counted)."""

    def __post_init__(self) -> None:
        for name in ("num_envs", "num_steps_per_env", "iterations", "save_interval", "num_learning_epochs",
                     "num_mini_batches"):
            check_number(getattr(self, name), f"ppo.{name}", integer=True, ge=1)
        for name in ("learning_rate", "clip_param", "desired_kl", "max_grad_norm"):
            check_number(getattr(self, name), f"ppo.{name}", gt=0)
        for name in ("entropy_coef", "value_loss_coef"):
            check_number(getattr(self, name), f"ppo.{name}", ge=0)
        check_number(self.gamma, "ppo.gamma", gt=0, le=1)
        check_number(self.lam, "ppo.lam", ge=0, le=1)
        check_number(self.seed, "ppo.seed", integer=True, ge=0, le=2**32 - 1)  # numpy's seed range
        check_number(self.torch_threads, "ppo.torch_threads", integer=True, ge=0)
        check_number(self.select_every, "ppo.select_every", integer=True, ge=0)
        check_device(self.device, "ppo.device")


RESUME_MAY_CHANGE = ("iterations", "device", "save_interval", "torch_threads", "cuda_graph")
""":class:`PPOConfig` fields a resumed run may change: how long, where and how it runs, not what it learns."""

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
        p = self.ppo
        per_batch = p.num_envs if self.residual.arch == "gru" else p.num_envs * p.num_steps_per_env
        if p.num_mini_batches > per_batch:
            unit = "worlds (a GRU is batched by world)" if self.residual.arch == "gru" else "samples per rollout"
            raise WresdynError(f"ppo.num_mini_batches = {p.num_mini_batches} is more than the {per_batch} {unit}")


def default_config() -> TrainConfig:
    """The default task: torque residual, MLP, Table I rewards, sized for a 2-core CPU demo run."""
    return TrainConfig()


def config_from_dict(d: dict) -> TrainConfig:
    """Inverse of ``dataclasses.asdict`` for :class:`TrainConfig` (lists back to tuples)."""

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

    return build(TrainConfig, d)


def parse_overrides(cfg: TrainConfig, items) -> dict:
    """``SECTION.FIELD=VALUE`` items (as on ``wresdyn train --set``) as ``{"SECTION.FIELD": value}``.

    SECTION is one of ``env``, ``residual``, ``rewards``, ``ppo``; VALUE is parsed as the field's type in ``cfg``
    (tuples as comma-separated numbers, booleans as true/false); a later item for the same field wins. Raises
    ``ValueError`` with a one-line message for an unknown key or a value of the wrong type.
    """
    sections = {f.name: getattr(cfg, f.name) for f in fields(cfg)}
    out = {}
    for item in items:
        key, sep, text = str(item).partition("=")
        section, dot, name = key.strip().partition(".")
        if not sep or not dot:
            raise ValueError(f"override {item!r} is not SECTION.FIELD=VALUE (sections: {', '.join(sections)})")
        if section not in sections:
            raise ValueError(f"override {item!r}: unknown section {section!r}; choose from {', '.join(sections)}")
        names = [f.name for f in fields(sections[section])]
        if name not in names:
            raise ValueError(f"override {item!r}: {section} has no field {name!r}; fields: {', '.join(names)}")
        out[f"{section}.{name}"] = _parse_like(getattr(sections[section], name), text.strip(), item)
    return out


def apply_overrides(cfg: TrainConfig, items) -> TrainConfig:
    """``cfg`` with ``SECTION.FIELD=VALUE`` overrides applied, as on ``wresdyn train --set`` (see
    :func:`parse_overrides`); a value the config refuses (:class:`WresdynError`) is a ``ValueError`` too."""
    return set_fields(cfg, parse_overrides(cfg, items))


def set_fields(cfg, values: dict):
    """``cfg`` (a frozen dataclass) with the nested fields ``{"ppo.seed": 1, ...}`` set, all at once: each
    config is rebuilt once, so checks across fields (:class:`TrainConfig`'s mini-batch check) see the final
    values whatever the order. Unknown fields raise ``TypeError``, refused values :class:`WresdynError`."""
    from dataclasses import replace

    direct, nested = {}, {}
    for dotted, value in values.items():
        head, _, rest = dotted.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            direct[head] = value
    for head, sub in nested.items():
        if not hasattr(cfg, head) or not is_dataclass(getattr(cfg, head)):
            raise TypeError(f"{type(cfg).__name__} has no section {head!r}")
        direct[head] = set_fields(getattr(cfg, head), sub)
    return replace(cfg, **direct)


def set_field(cfg, dotted: str, value):
    """``cfg`` (a frozen dataclass) with the nested field at ``dotted`` (e.g. ``"ppo.seed"``) set to ``value``."""
    return set_fields(cfg, {dotted: value})


def _parse_like(current, text: str, item):
    """``text`` parsed as the type of ``current`` (bool, int, float, str, tuple of numbers)."""
    try:
        if isinstance(current, bool):
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError
            return text.lower() in ("true", "1")
        if isinstance(current, tuple):
            kind = type(current[0]) if current else float
            return tuple(kind(v) for v in text.split(",") if v.strip())
        return type(current)(text)
    except ValueError:
        raise ValueError(f"override {item!r}: {text!r} is not a {type(current).__name__}") from None


def runner_cfg(cfg: TrainConfig, run_name: str = "") -> dict:
    """The rsl-rl ``OnPolicyRunner`` configuration dict."""
    from .residual import actor_critic_cfg

    actor, critic = actor_critic_cfg(cfg.residual)
    p = cfg.ppo
    return {
        "num_steps_per_env": p.num_steps_per_env,
        "save_interval": p.save_interval,
        "obs_groups": {"actor": ["policy"], "critic": ["critic"]},
        "algorithm": {
            "class_name": "PPO",
            "num_learning_epochs": p.num_learning_epochs,
            "num_mini_batches": p.num_mini_batches,
            "clip_param": p.clip_param,
            "gamma": p.gamma,
            "lam": p.lam,
            "value_loss_coef": p.value_loss_coef,
            "entropy_coef": p.entropy_coef,
            "learning_rate": p.learning_rate,
            "max_grad_norm": p.max_grad_norm,
            "schedule": "adaptive",
            "desired_kl": p.desired_kl,
        },
        "actor": actor,
        "critic": critic,
        "logger": "tensorboard",
        "run_name": run_name,
        "check_for_nan": True,  # train() turns it off where the environment's step is graph-replayed
    }


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The rsl-rl checkpoint ``model_<it>.pt`` with the highest iteration in ``run_dir``, if any."""
    found = [(int(m.group(1)), p) for p in Path(run_dir).glob("model_*.pt") if (m := re.fullmatch(r"model_(\d+)\.pt", p.name))]
    return max(found)[1] if found else None


def _dataset_info(dataset) -> dict:
    return {"robot_file": str(getattr(dataset, "robot_file", "")), "robot_sha256": getattr(dataset, "robot_sha256", ""),
            "rate_hz": float(dataset.rate_hz), "joint_names": list(dataset.joint_names),
            "train": [t.name for t in dataset.split("train")]}


@dataclass(frozen=True)
class Ranks:
    """Where this process stands in a ``torchrun`` launch (``WORLD_SIZE``, ``RANK``, ``LOCAL_RANK``); one process
    of rank 0 without it."""

    world: int = 1
    rank: int = 0
    local_rank: int = 0

    @property
    def main(self) -> bool:
        """The process that writes the run folder (config, checkpoints, selection, export)."""
        return self.rank == 0

    @classmethod
    def from_env(cls) -> "Ranks":
        import os

        try:
            r = cls(int(os.environ.get("WORLD_SIZE", "1")), int(os.environ.get("RANK", "0")),
                    int(os.environ.get("LOCAL_RANK", "0")))
        except ValueError:
            raise RunError("WORLD_SIZE, RANK and LOCAL_RANK must be integers (set by torchrun)") from None
        if not (r.world >= 1 and 0 <= r.rank < r.world and 0 <= r.local_rank < r.world):
            raise RunError(f"inconsistent torchrun ranks: WORLD_SIZE={r.world} RANK={r.rank} LOCAL_RANK={r.local_rank}")
        return r

    def device(self, device: str) -> str:
        """This process's device: ``cuda:<LOCAL_RANK>`` for a CUDA run under torchrun (one GPU per process),
        else ``device``."""
        return f"cuda:{self.local_rank}" if self.world > 1 and device.startswith("cuda") else device

    def num_envs(self, total: int) -> int:
        """This process's share of ``total`` environments."""
        if total % self.world:
            raise RunError(f"ppo.num_envs = {total} does not split over {self.world} processes; use a multiple of "
                           f"{self.world}")
        return total // self.world


CHECKPOINT_KEYS = ("actor_state_dict", "critic_state_dict", "optimizer_state_dict", "iter")
"""What an rsl-rl PPO checkpoint holds (``PPO.save`` plus the runner's iteration)."""


class Runner(OnPolicyRunner):
    """rsl-rl's ``OnPolicyRunner`` that never unpickles: checkpoints are written and read as weights only.

    rsl-rl 5.5 loads with ``torch.load(weights_only=False)``, which runs whatever a checkpoint file asks for.
    What it saves (state dicts, the optimizer state, the iteration, ``infos=None``) is all tensors and plain
    containers, so the same files load with ``weights_only=True``; :func:`save_checkpoint` checks that on every
    save and writes atomically, so a run killed mid-save resumes from the previous checkpoint.
    """

    def _configure_multi_gpu(self) -> None:
        """rsl-rl's multi-GPU set-up (NCCL, one GPU per process); CPU processes under torchrun (tests, CPU nodes)
        get the same data-parallel PPO over gloo, NCCL being GPU-only."""
        import torch

        r = Ranks.from_env()
        if str(self.device).startswith("cuda") or r.world <= 1:
            return super()._configure_multi_gpu()
        self.gpu_world_size, self.is_distributed = r.world, True
        self.gpu_local_rank, self.gpu_global_rank = r.local_rank, r.rank
        self.cfg["multi_gpu"] = {"global_rank": r.rank, "local_rank": r.local_rank, "world_size": r.world}
        if not torch.distributed.is_initialized():
            torch.distributed.init_process_group(backend="gloo", rank=r.rank, world_size=r.world)

    def save(self, path: str, infos: dict | None = None) -> None:
        data = self.alg.save()
        data["iter"] = self.current_learning_iteration
        data["infos"] = infos
        save_checkpoint(data, path)
        self.logger.save_model(path, self.current_learning_iteration)

    def load(self, path: str, load_cfg: dict | None = None, strict: bool = True, map_location: str | None = None):
        """What ``OnPolicyRunner.load`` does, reading the file with :func:`load_checkpoint`; a checkpoint that
        does not fit these networks is a one-line :class:`RunError` naming the file."""
        data = load_checkpoint(path, map_location, keys=CHECKPOINT_KEYS)
        if isinstance(data["iter"], bool) or not isinstance(data["iter"], int):
            raise RunError(f"{path}: not a checkpoint of this project (iteration {data['iter']!r})")
        try:
            load_iteration = self.alg.load(data, load_cfg, strict)
        except (RuntimeError, KeyError, ValueError, TypeError, AttributeError) as e:
            # load_state_dict lists every mismatching tensor over many lines; the first one says enough
            lines = [ln.strip() for ln in str(e).splitlines() if ln.strip()]
            detail = lines[1] if len(lines) > 1 and lines[0].startswith("Error(s) in loading") else (lines or [""])[0]
            raise RunError(f"{path}: does not fit this run's networks ({detail[:160]})") from None
        if load_iteration:
            self.current_learning_iteration = data["iter"]
        return data.get("infos")


def on_iteration(runner, progress, each=None) -> None:
    """Advance ``progress`` (a :func:`wresdyn.progress.bar`) by one after each PPO iteration of ``runner``, noting
    the mean episode reward, and call ``each(kw)`` with what rsl-rl logs of it (``collect_time``, ``learn_time``, ...).

    rsl-rl's ``OnPolicyRunner.learn`` reports an iteration only through ``runner.logger.log``, so the hook wraps it.
    """
    log_iteration = runner.logger.log

    def logged(*a, **kw):
        out = log_iteration(*a, **kw)
        rewards = getattr(runner.logger, "rewbuffer", None)  # the episodes finished in the last 100 resets
        progress.update(1, f"reward {float(np.mean(rewards)):.3g}" if rewards else None)
        if each is not None:
            each(kw)
        return out

    runner.logger.log = logged


def _check_resume(run_dir: Path, cfg_path: Path, saved: dict) -> None:
    """Refuse to resume ``run_dir`` with another configuration or other data, naming what changed."""
    if not cfg_path.is_file():
        raise RunError(f"{run_dir} holds checkpoints but no config.json, so what they learned is unknown; "
                       "choose another folder")
    try:
        old = json.loads(cfg_path.read_text())
        old_cfg = old["config"]
    except (ValueError, KeyError, TypeError):
        raise RunError(f"{cfg_path}: not a run configuration written by `wresdyn train`") from None
    # a run may be extended, or moved to another device or machine
    check_resume(run_dir, old_cfg, saved["config"], may_change=[f"ppo.{k}" for k in RESUME_MAY_CHANGE])
    # a run folder may hold only some of the identity fields (the others unrecorded): compare those it has
    old_data = old.get("dataset") or {}
    keys = [k for k in DATASET_IDENTITY if k in old_data]
    check_resume(run_dir, {"dataset": {k: old_data[k] for k in keys}},
                 {"dataset": {k: saved["dataset"][k] for k in keys}}, what="data")


def train(dataset, robot, cfg: TrainConfig, run_dir: str | Path, resume: bool = True,
          data_path: str | Path | None = None, stop_below: float | None = None, log=print) -> dict:
    """Train a residual with PPO on the ``train`` split of ``dataset``; resume from the latest checkpoint.

    Args:
        dataset: A :class:`wresdyn.data.dataset.Dataset` (only ``q``, ``qd``, ``qdd``, ``q_cmd`` are read).
        robot: The nominal robot the simulator uses.
        cfg: The run configuration; must equal the saved one when resuming, except :data:`RESUME_MAY_CHANGE`.
        run_dir: Run folder (created).
        resume: Continue from ``model_<it>.pt`` in ``run_dir``; with ``False`` an existing checkpoint is an error.
        data_path: Where ``dataset`` was read from, recorded in ``config.json`` for ``wresdyn eval``.
        stop_below: Stop at the first validation check whose error is at or below this [rad] (time to fidelity,
            ``benchmarks/time_to_fidelity.py``); the run is then exported as if it had ended there.
        log: Printer of the run's lines; a :class:`wresdyn.progress.Log` also draws a bar over the iterations.

    Under ``torchrun`` (``WORLD_SIZE`` > 1) each process trains ``num_envs / WORLD_SIZE`` worlds on its own device
    (``cuda:<LOCAL_RANK>``, or the CPU over gloo) with seed ``seed + RANK``, and rsl-rl averages the gradients
    across processes; rank 0 alone writes the run folder and selects on validation, and every rank resumes from
    the same checkpoint.

    Returns:
        The training summary written to ``train_summary.json``.

    Raises:
        RunError: The run folder holds another configuration, other data (:data:`DATASET_IDENTITY`) or a
            checkpoint that is not a weights-only rsl-rl checkpoint of these networks.
    """
    import torch

    from ..progress import bar, into_file
    from .replay_env import ReplayEnv
    from .residual import obs_stats, policy_from_actor
    from .selection import ValidationScore

    run_dir = Path(run_dir)
    ranks = Ranks.from_env()
    device = ranks.device(cfg.ppo.device)
    num_envs = ranks.num_envs(cfg.ppo.num_envs)
    train_trajs = dataset.split("train")
    if not train_trajs:
        raise RunError("the dataset has no 'train' trajectories")
    if list(dataset.joint_names) != list(robot.joint_names):
        raise RunError(f"dataset joints {list(dataset.joint_names)[:3]}... do not match the robot's "
                       f"{list(robot.joint_names)[:3]}...")
    saved = {"config": asdict(cfg), "dataset": _dataset_info(dataset),
             "data_path": None if data_path is None else str(Path(data_path).resolve())}
    cfg_path = run_dir / "config.json"
    ckpt = latest_checkpoint(run_dir)
    if ckpt is not None and not resume:
        raise RunError(f"{run_dir} already holds checkpoints ({ckpt.name}); resume it or choose another folder")
    if ckpt is not None:
        _check_resume(run_dir, cfg_path, saved)

    if cfg.ppo.torch_threads > 0:
        torch.set_num_threads(cfg.ppo.torch_threads)
    seed = cfg.ppo.seed + ranks.rank
    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)
    mean, std = obs_stats(train_trajs)
    env = ReplayEnv(robot, train_trajs, dataset.rate_hz, num_envs, cfg.env, cfg.residual, cfg.rewards,
                    device=device, seed=seed, obs_mean=mean, obs_std=std, graph=cfg.ppo.cuda_graph,
                    weights=dataset.fit_weights())
    if ranks.main:
        run_dir.mkdir(parents=True, exist_ok=True)
    log(f"{num_envs} replay worlds on {env.device}, {type(env.sim.solver).__name__}")  # writes the waiting lines too
    rcfg = runner_cfg(cfg, run_dir.name)
    rcfg["check_for_nan"] = not env.graph  # a graph-replayed step is not checked per step (a host sync each)
    rsl_rl_log = run_dir / "train.log" if ranks.main else None
    with into_file(rsl_rl_log):  # rsl-rl prints the networks
        runner = Runner(env, rcfg, log_dir=str(run_dir) if ranks.main else None, device=str(env.device))
    start = 0
    if ckpt is not None:
        runner.load(str(ckpt), map_location=str(env.device))
        start = runner.current_learning_iteration + 1
        runner.current_learning_iteration = start
        log(f"resuming {run_dir} from {ckpt.name} at iteration {start}")
    if ranks.main:  # written once the checkpoint has loaded: a refused resume leaves the folder as it was
        tmp = cfg_path.with_name(cfg_path.name + ".tmp")
        tmp.write_text(json.dumps(saved, indent=2))
        tmp.replace(cfg_path)
    validation = dataset.split("validation") if ranks.main else []
    score = ValidationScore(robot, validation, dataset.rate_hz, cfg.env.solver, device,
                            physics=env.physics, weights=dataset.fit_weights()) if validation else None
    best_path = run_dir / "best.pt"
    best = load_checkpoint(best_path, keys=("actor", "meta")) if start and best_path.is_file() else None
    curve = best["meta"]["validation_curve"] if best else []
    every = cfg.ppo.select_every or max(1, cfg.ppo.iterations // 10)
    if score is not None and start == 0 and env.physics is not None:
        # on identified physics (the hybrid) the near-zero residual at the start is a candidate too: the hybrid is
        # never selected worse than the identified model alone
        value = score(policy_from_actor(runner.alg.get_policy(), mean, std, env.scale.cpu().numpy(),
                                        cfg.residual.kind, cfg.residual.action_gain))
        curve.append({"iteration": 0, "validation": value, "diverged": score.last_diverged})
        log(f"validation at the start: {value:.4f} rad")
        actor = {k: v.detach().cpu().clone() for k, v in runner.alg.get_policy().state_dict().items()}
        best = {"actor": actor, "meta": {"iteration": 0, "validation": value, "validation_curve": curve}}
        save_checkpoint(best, best_path)
    phases = {"collect": 0.0, "learn": 0.0}  # rsl-rl's own split of each iteration [s]

    def timed(kw):
        phases["collect"] += kw.get("collect_time", 0.0)
        phases["learn"] += kw.get("learn_time", 0.0)

    progress = bar(log, cfg.ppo.iterations, "train", start)
    on_iteration(runner, progress, timed)
    t0, eval_s, done = time.perf_counter(), 0.0, start
    reached = None
    with progress:
        while done < cfg.ppo.iterations and reached is None:
            # learn up to the next selection point (rsl-rl continues from current_learning_iteration)
            n = min(every - done % every, cfg.ppo.iterations - done)
            runner.current_learning_iteration = done
            with into_file(rsl_rl_log):  # rsl-rl's per-iteration table
                runner.learn(n)
            done += n
            if score is not None:
                t_eval = time.perf_counter()
                value = score(policy_from_actor(runner.alg.get_policy(), mean, std, env.scale.cpu().numpy(),
                                                cfg.residual.kind, cfg.residual.action_gain))
                curve.append({"iteration": done, "validation": value, "diverged": score.last_diverged,
                              "wall_s": t_eval - t0 - eval_s})
                log(f"validation after {done} iterations: {value:.4f} rad")
                if stop_below is not None and value <= stop_below:
                    reached = done
                if best is None or value < best["meta"]["validation"]:
                    actor = {k: v.detach().cpu().clone() for k, v in runner.alg.get_policy().state_dict().items()}
                    best = {"actor": actor, "meta": {"iteration": done, "validation": value}}
                best["meta"]["validation_curve"] = curve
                save_checkpoint(best, best_path)
                eval_s += time.perf_counter() - t_eval
            if ranks.world > 1 and stop_below is not None:  # every rank stops where rank 0 reached the target
                flag = torch.tensor([-1 if reached is None else reached], device=env.device)
                torch.distributed.broadcast(flag, src=0)
                reached = None if int(flag) < 0 else int(flag)
    wall = time.perf_counter() - t0 - eval_s
    todo = done - start
    it_time = runner.logger.tot_time  # collection + update, without start-up
    steps = env.steps_total * ranks.world  # every rank steps as many worlds
    summary = {
        "iterations": cfg.ppo.iterations,
        "iterations_this_session": todo,
        "env_steps_this_session": steps,
        "wall_s_this_session": wall,
        "s_per_iteration": it_time / todo if todo else None,
        "env_steps_per_s": steps / env.step_seconds if env.step_seconds else None,
        "training_steps_per_s": steps / it_time if it_time else None,
        "collect_s_per_iteration": phases["collect"] / todo if todo else None,
        "learn_s_per_iteration": phases["learn"] / todo if todo else None,
        "collection_steps_per_s": steps / phases["collect"] if phases["collect"] else None,
        "diverged_this_session": env.diverged_total,
        "device": str(env.device),
        "processes": ranks.world,
        "cuda_graph": env.graph,
        "stopped_at_target": reached,
        "solver": type(env.sim.solver).__name__,
        "selected_iteration": best["meta"]["iteration"] if best else cfg.ppo.iterations,
        "selected_validation": best["meta"]["validation"] if best else None,
        "validation_curve": curve,
    }
    if ranks.main:
        actor = runner.alg.get_policy()
        if best is not None:  # export the residual chosen on validation, not merely the last
            # into the actor itself: training is over and its last checkpoint written, and a deepcopy of it fails on
            # the non-leaf outputs its distribution keeps from the last update
            actor.load_state_dict(best["actor"])
        export(actor, run_dir, cfg, mean, std, env.scale.cpu().numpy(), dataset)
        if env.physics is not None:  # the run carries the model it was trained on: evaluation replays with it
            env.physics.save(run_dir / "physics.json")
        (run_dir / "train_summary.json").write_text(json.dumps(summary, indent=2))
    if ranks.world > 1 and torch.distributed.is_initialized():
        # a finished run tears its process group down while the interpreter is alive, every rank once rank 0 has
        # written the run: a gloo group left to interpreter exit aborts a rank now and then ("terminate called
        # without an active exception", pytorch#190489). A failed rank skips this; torchrun stops the others.
        torch.distributed.barrier()
        torch.distributed.destroy_process_group()
    return summary


def export(actor, run_dir: Path, cfg: TrainConfig, mean, std, scale, dataset) -> None:
    """Write ``policy.pt`` (a ``torch.export`` archive), ``policy.onnx`` and ``residual.json`` for a trained actor."""
    from .residual import export_run_files, policy_from_actor

    policy = policy_from_actor(actor, mean, std, scale, cfg.residual.kind, cfg.residual.action_gain)
    export_run_files(policy, run_dir, dataset, arch=cfg.residual.arch, action_gain=cfg.residual.action_gain)


def load_policy(run_dir: str | Path):
    """The exported residual of a run: ``(policy, meta)`` with ``policy(obs) -> residual``
    (:class:`~wresdyn.export.program.ExportedResidual`, on the CPU) and ``meta`` its ``residual.json``."""
    from .network_file import load_residual

    run_dir = Path(run_dir)
    path, meta_path = run_dir / "policy.pt", run_dir / "residual.json"
    if not path.is_file() or not meta_path.is_file():
        raise RunError(f"{run_dir}: no exported residual (policy.pt, residual.json); train it first")
    return load_residual(path), json.loads(meta_path.read_text())
