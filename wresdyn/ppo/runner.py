"""rsl-rl glue shared by the PPO learners (the residual, :mod:`wresdyn.ppo.trainer`; the skills,
:mod:`wresdyn.skills.train`): the runner, its checkpoints, its progress and its processes.

- :class:`Runner`: rsl-rl's ``OnPolicyRunner`` that reads and writes checkpoints ``model_<it>.pt`` as weights only
  (:func:`~wresdyn.learn.runs.load_checkpoint`), and runs data-parallel over gloo for CPU processes under torchrun.
- :func:`rsl_runner_cfg`: the runner configuration both learners fill (PPO, adaptive learning rate, tensorboard).
- :func:`make_runner`, :func:`resume_runner`, :func:`learn`: build a runner with rsl-rl's printing kept in the run's
  ``train.log``, continue it from a checkpoint, run its iterations.
- :func:`on_iteration`: a progress bar advanced by rsl-rl's per-iteration log.
- :class:`Ranks`: where this process stands in a ``torchrun`` launch.
"""

from __future__ import annotations

import json
import os
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rsl_rl.runners import OnPolicyRunner

from ..learn.runs import RunError, RunnerFolder, check_resume, load_checkpoint, save_checkpoint
from ..progress import into_file
from .episode_log import defer_episode_log

__all__ = ["Ranks", "Runner", "CHECKPOINT_KEYS", "rsl_runner_cfg", "make_runner", "resume_runner", "learn",
           "on_iteration", "seed_processes", "latest_checkpoint", "UpgradingRunnerFolder"]


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

    def num_worlds(self, total: int) -> int:
        """This process's share of ``total`` simulated worlds (rsl-rl's environments)."""
        if total % self.world:
            raise RunError(f"num_worlds = {total} does not split over {self.world} processes; use a multiple of "
                           f"{self.world}")
        return total // self.world

    def close(self) -> None:
        """Tear a finished run's process group down, every rank once rank 0 has written the run.

        Done while the interpreter is alive: a gloo group left to interpreter exit aborts a rank now and then
        ("terminate called without an active exception", pytorch#190489). An NCCL group is left to the interpreter's
        exit instead: with an all-reduce captured in a CUDA graph (the graph update) ``destroy_process_group`` waits
        forever on both ranks of an H200 pair (``benchmarks/results/speed/h200x2_20261130f/ppo_two_process``), and
        NCCL's teardown at exit returns. A failed rank skips this; torchrun stops the others."""
        import torch

        if self.world > 1 and torch.distributed.is_initialized():
            torch.distributed.barrier()
            if torch.distributed.get_backend() != "nccl":
                torch.distributed.destroy_process_group()


CHECKPOINT_KEYS = ("actor_state_dict", "critic_state_dict", "optimizer_state_dict", "iter")
"""What an rsl-rl PPO checkpoint holds (``PPO.save`` plus the runner's iteration)."""


class Runner(OnPolicyRunner):
    """rsl-rl's ``OnPolicyRunner`` that never unpickles: checkpoints are written and read as weights only.

    rsl-rl 5.5 loads with ``torch.load(weights_only=False)``, which runs whatever a checkpoint file asks for.
    What it saves (state dicts, the optimizer state, the iteration, ``infos=None``) is all tensors and plain
    containers, so the same files load with ``weights_only=True``; :func:`save_checkpoint` checks that on every
    save and writes atomically, so a run killed mid-save resumes from the previous checkpoint.
    """

    def __init__(self, env, train_cfg: dict, log_dir: str | None = None, device: str = "cpu") -> None:
        super().__init__(env, train_cfg, log_dir=log_dir, device=device)
        if train_cfg.get("deferred_episode_log"):
            defer_episode_log(self.logger)

    def _configure_multi_gpu(self) -> None:
        """rsl-rl's multi-GPU set-up (NCCL, one GPU per process); CPU processes under torchrun (tests, CPU nodes)
        get the same data-parallel PPO over gloo, NCCL being GPU-only. A later runner of the same process (the
        next skill of a benchmark) joins the process group the first one started: a default group started again
        after ``destroy_process_group`` reuses the first one's rendezvous keys and waits on its closed ports."""
        import torch

        r = Ranks.from_env()
        cuda = str(self.device).startswith("cuda")
        if r.world <= 1 or (cuda and not torch.distributed.is_initialized()):
            return super()._configure_multi_gpu()
        if cuda:
            if self.device != f"cuda:{r.local_rank}":
                raise RunError(f"device {self.device} is not this process's cuda:{r.local_rank} (LOCAL_RANK)")
            torch.cuda.set_device(r.local_rank)
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


def rsl_runner_cfg(*, num_steps_per_env: int, save_interval: int, actor: dict, critic: dict,
                   critic_groups=("critic",), run_name: str = "", one_sync_update: bool = False,
                   packed_update: bool = False, graph_update: bool = False, compile_mode: str = "",
                   deferred_episode_log: bool = False, **algorithm) -> dict:
    """The rsl-rl ``OnPolicyRunner`` configuration dict: PPO with the adaptive learning rate, its settings
    ``algorithm`` (``num_learning_epochs``, ``num_mini_batches``, ``clip_param``, ``gamma``, ``lam``,
    ``value_loss_coef``, ``entropy_coef``, ``learning_rate``, ``max_grad_norm``, ``desired_kl``,
    ``use_mixed_precision``), the ``actor`` and ``critic`` model configs, tensorboard logging. The actor sees the
    observation group ``policy``, the critic ``critic_groups`` (more than the actor's: an asymmetric actor-critic).
    ``one_sync_update``: the update of :class:`~wresdyn.ppo.update.OneSyncPPO` instead of rsl-rl's own;
    ``packed_update`` (without ``one_sync_update``): :class:`~wresdyn.ppo.packed_update.PackedPPO`, rsl-rl's update
    bit for bit with fewer collectives and host waits; ``graph_update`` (without ``one_sync_update``):
    :class:`~wresdyn.ppo.graph_update.GraphPPO`, the packed update with each mini-batch's step one CUDA graph replay;
    ``compile_mode``: rsl-rl's ``torch.compile`` of the actor and critic (``""``: none); ``deferred_episode_log``:
    the episode bookkeeping copied to the host once per iteration (:mod:`~wresdyn.ppo.episode_log`; the key is set only
    when true)."""
    ppo = ("wresdyn.ppo.update:OneSyncPPO" if one_sync_update else "wresdyn.ppo.graph_update:GraphPPO" if graph_update
           else "wresdyn.ppo.packed_update:PackedPPO" if packed_update else "PPO")
    extra = {"deferred_episode_log": True} if deferred_episode_log else {}
    return {
        **extra,
        "num_steps_per_env": num_steps_per_env,
        "save_interval": save_interval,
        "obs_groups": {"actor": ["policy"], "critic": list(critic_groups)},
        "algorithm": {"class_name": ppo, **algorithm, "schedule": "adaptive"},
        "torch_compile_mode": compile_mode or None,
        "actor": actor,
        "critic": critic,
        "logger": "tensorboard",
        "run_name": run_name,
        "check_for_nan": True,
    }


def seed_processes(seed: int, torch_threads: int | None) -> None:
    """Pin torch's CPU threads (``None`` leaves torch's default) and seed torch and numpy's global generator (rsl-rl
    and the environments draw from them)."""
    import torch

    if torch_threads:
        torch.set_num_threads(torch_threads)
    torch.manual_seed(seed)
    np.random.seed(seed % 2**32)


def make_runner(env, cfg: dict, run_dir: Path, main: bool = True) -> Runner:
    """A :class:`Runner` on ``env`` with the configuration ``cfg`` (:func:`rsl_runner_cfg`), writing its
    tensorboard events and checkpoints into ``run_dir`` and the networks it prints into ``run_dir/train.log``;
    ``main`` false (a torchrun rank other than 0): it writes nothing."""
    with into_file(run_dir / "train.log" if main else None):
        return Runner(env, cfg, log_dir=str(run_dir) if main else None, device=str(env.device))


def resume_runner(runner: Runner, ckpt: Path, run_dir: Path, log=print) -> int:
    """Load the checkpoint ``ckpt`` of ``run_dir`` into ``runner`` and return the iteration to continue from."""
    runner.load(str(ckpt), map_location=str(runner.env.device))
    start = runner.current_learning_iteration + 1
    runner.current_learning_iteration = start
    log(f"resuming {run_dir} from {ckpt.name} at iteration {start}")
    return start


def learn(runner: Runner, start: int, n: int, log_file: Path | None) -> None:
    """Run ``n`` PPO iterations of ``runner`` from iteration ``start``, rsl-rl's per-iteration tables into
    ``log_file`` (``None``: nowhere)."""
    runner.current_learning_iteration = start
    with into_file(log_file):
        runner.learn(n)


def on_iteration(runner, progress, each=None, phases: dict | None = None) -> None:
    """Advance ``progress`` (a :func:`wresdyn.progress.bar`) by one after each PPO iteration of ``runner``, noting
    the mean episode reward, add rsl-rl's ``collect_time`` and ``learn_time`` of it [s] into ``phases["collect"]`` and
    ``phases["learn"]``, and call ``each(kw)`` with what rsl-rl logs of it.

    rsl-rl's ``OnPolicyRunner.learn`` reports an iteration only through ``runner.logger.log``, so the hook wraps it.
    """
    log_iteration = runner.logger.log

    def logged(*a, **kw):
        out = log_iteration(*a, **kw)
        rewards = getattr(runner.logger, "rewbuffer", None)  # the episodes finished in the last 100 resets
        progress.update(1, f"reward {float(np.mean(rewards)):.3g}" if rewards else None)
        if phases is not None:
            phases["collect"] += kw.get("collect_time", 0.0)
            phases["learn"] += kw.get("learn_time", 0.0)
        if each is not None:
            each(kw)
        return out

    runner.logger.log = logged


def latest_checkpoint(run_dir: str | Path) -> Path | None:
    """The rsl-rl checkpoint ``model_<it>.pt`` with the highest iteration in ``run_dir``, if any."""
    found = [(int(m.group(1)), p) for p in Path(run_dir).glob("model_*.pt")
             if (m := re.fullmatch(r"model_(\d+)\.pt", p.name))]
    return max(found)[1] if found else None


class UpgradingRunnerFolder(RunnerFolder):
    """A :class:`~wresdyn.learn.runs.RunnerFolder` whose resume check reads the saved ``config.json`` through
    ``upgrade``: a record that keeps a field under another name (the world count as ``ppo.num_envs``) is compared as
    the record it stands for."""

    def __init__(self, path, record: dict, may_change=(), key: str | None = None, writer: str = "this learner",
                 upgrade=lambda record: record) -> None:
        super().__init__(path, record, may_change, key, writer)
        self.upgrade = upgrade

    def check(self, checkpoint) -> dict | None:
        if checkpoint is None:
            return None
        path = self.path / "config.json"
        try:
            old = json.loads(path.read_text()) if path.is_file() else None
        except ValueError:
            old = None
        saved = old.get(self.key) if isinstance(old, dict) and self.key else old
        if not isinstance(saved, dict):
            return super().check(checkpoint)  # refused, in the runner folder's words
        old = self.upgrade(old)
        check_resume(self.path, old[self.key] if self.key else old, self.config, self.may_change)
        return old
