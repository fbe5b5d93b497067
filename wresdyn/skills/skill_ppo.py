"""Train a tracking skill with PPO (rsl-rl) on a plant, or fine-tune one; checkpoints and resume.

A run folder holds ``config.json`` (what it trains: task, PPO, setting, the policy it started from), rsl-rl
checkpoints ``model_<it>.pt`` (written and read as weights only, :class:`wresdyn.ppo.runner.Runner`),
``policy.pt`` (a ``torch.export`` archive, :mod:`wresdyn.learn.network_file`: observation (N, 6n) -> action (N, n), the
deterministic mean), ``train_summary.json`` and rsl-rl's per-iteration log ``train.log``. A run killed mid-way resumes
from its last checkpoint; one asked to resume with another configuration is refused in one line, naming what
changed (the folder is a :class:`wresdyn.ppo.runner.UpgradingRunnerFolder`). A run that has already trained its
iterations and passes that check is reused as it is (:func:`finished_skill`): nothing is rebuilt or rewritten. The
world count is the plant's, recorded as ``num_worlds``; a ``config.json`` that keeps it as ``ppo.num_envs`` reads the
same (:func:`upgrade_record`). The rsl-rl glue (runner, checkpoints, progress) is the residual learner's,
:mod:`wresdyn.ppo.runner`.

Under ``torchrun`` a skill trains data-parallel as the residual does (:func:`wresdyn.ppo.trainer.train`): each process
steps its share of the worlds on its own device (:func:`rank_share`), seeded ``seed + RANK``, rsl-rl averages the
gradients, rank 0 alone writes the run folder, and every rank resumes from the same checkpoint.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch

from ..learn.network_file import load_program, save_program
from ..ppo.runner import (Ranks, UpgradingRunnerFolder, latest_checkpoint, learn, make_runner, on_iteration,
                          resume_runner, rsl_runner_cfg, seed_processes)
from ..progress import bar
from .skill_config import SkillPPOConfig

__all__ = ["SkillPPOConfig", "train_skill", "finished_skill", "load_skill", "rank_share", "runner_cfg",
           "RESUME_MAY_CHANGE", "upgrade_record"]

RESUME_MAY_CHANGE = ("ppo.iterations", "ppo.device", "ppo.torch_threads", "ppo.one_sync_update")
"""What a resumed skill run may change: a run may be extended, or moved to another device or machine."""


def runner_cfg(cfg: SkillPPOConfig, critic_groups=("policy",)) -> dict:
    """rsl-rl's runner config; ``critic_groups``: the observation groups the critic sees (the actor sees
    ``policy``; more groups make an asymmetric actor-critic)."""
    dist = {"class_name": "GaussianDistribution", "init_std": cfg.init_std, "std_type": "log"}
    actor = {"class_name": "wresdyn.learn.residual:ResidualMLPModel", "hidden_dims": list(cfg.hidden_dims),
             "activation": "elu", "obs_normalization": True, "distribution_cfg": dist, "output_gain": cfg.output_gain}
    critic = {"class_name": "MLPModel", "hidden_dims": list(cfg.hidden_dims), "activation": "elu",
              "obs_normalization": True}
    return rsl_runner_cfg(
        num_steps_per_env=cfg.num_steps_per_env, save_interval=cfg.save_interval, actor=actor, critic=critic,
        critic_groups=critic_groups, num_learning_epochs=cfg.num_learning_epochs, num_mini_batches=cfg.num_mini_batches,
        clip_param=0.2, gamma=cfg.gamma, lam=cfg.lam, value_loss_coef=1.0, entropy_coef=cfg.entropy_coef,
        learning_rate=cfg.learning_rate, max_grad_norm=1.0, desired_kl=cfg.desired_kl,
        one_sync_update=cfg.one_sync_update)


def rank_share(num_worlds: int, device: str) -> tuple[int, str]:
    """This process's worlds and device for a skill of ``num_worlds`` worlds on ``device``: all of them in one process,
    ``num_worlds / WORLD_SIZE`` on ``cuda:<LOCAL_RANK>`` (or the CPU) under torchrun, which becomes the process's
    current CUDA device before its worlds are built (as rsl-rl's runner sets it later)."""
    ranks = Ranks.from_env()
    here = ranks.device(device)
    if ranks.world > 1 and here.startswith("cuda"):
        torch.cuda.set_device(here)
    return ranks.num_worlds(num_worlds), here


def upgrade_record(record: dict) -> dict:
    """A skill run's ``config.json`` record with the world count as ``num_worlds``, moved there from ``ppo.num_envs``
    where a record keeps it in the PPO config (a record without it is returned as it is)."""
    ppo = record.get("ppo")
    if not isinstance(ppo, dict) or "num_envs" not in ppo:
        return record
    ppo = dict(ppo)
    num_worlds = ppo.pop("num_envs")
    return {**record, "ppo": ppo, "num_worlds": record.get("num_worlds", num_worlds)}


def _set_std(actor, std: float) -> None:
    """Set the Gaussian action noise of an rsl-rl actor to ``std`` on every action."""
    dist = actor.distribution
    with torch.no_grad():
        if dist.std_type == "log":
            dist.log_std_param.fill_(float(np.log(std)))
        else:
            dist.std_param.fill_(std)


def train_skill(env, cfg: SkillPPOConfig, run_dir, *, init: str | Path | None = None, meta: dict | None = None,
                log=print) -> dict:
    """PPO on ``env`` (a :class:`~wresdyn.skills.env.TrackingEnv`) for ``cfg.iterations``; resumes ``run_dir``.

    Args:
        env: The environment (its plant is the training ground).
        cfg: PPO settings.
        run_dir: Run folder (created).
        init: A skill run folder to start from (fine-tuning): its last checkpoint's actor, critic and optimiser;
            the iteration count starts at 0.
        meta: What else identifies the run (setting, motions), stored in ``config.json`` and checked on resume.
        log: Printer of the run's lines; a :class:`wresdyn.progress.Log` also draws a bar over the iterations,
            named after the run folder (the policy).

    Under torchrun ``env`` holds this process's share of the worlds on its device (:func:`rank_share`), the run's
    ``num_worlds`` all of them;
    the summary's counts are those of rank 0's worlds, its env-steps those of every process. The process group stays
    up for the next skill of the process; ``Ranks.from_env().close()`` ends it once the last is trained.

    A run that has already trained ``cfg.iterations`` is reused (:func:`finished_skill`): nothing is trained or
    written, and its stored summary is returned.

    Returns:
        The summary written to ``train_summary.json`` (for a reused run, the one it holds).
    """
    run_dir, ranks = Path(run_dir), Ranks.from_env()
    run, ckpt, done = _checked(run_dir, cfg, env.cfg_dict, env.num_envs, init, meta)
    if done is not None:
        log(f"{run_dir.name}: done earlier ({cfg.iterations} iterations), reused")
        return done
    seed_processes(cfg.seed + ranks.rank, cfg.torch_threads)
    if ranks.main:
        run_dir.mkdir(parents=True, exist_ok=True)
    runner = make_runner(env, runner_cfg(cfg, getattr(env, "critic_groups", ("policy",))), run_dir, ranks.main)
    log_file = run_dir / "train.log" if ranks.main else None
    start = 0
    if ckpt is not None:
        start = resume_runner(runner, ckpt, run_dir, log)
    elif init is not None:
        _start_from(runner, init, cfg.restart_std)
    if ranks.main:
        run.write_config()
    todo = max(cfg.iterations - start, 0)
    t0 = time.perf_counter()
    phases = {"collect": 0.0, "learn": 0.0}  # rsl-rl's seconds of each, summed over this session's iterations

    if todo:
        with bar(log, cfg.iterations, run_dir.name, start) as progress:
            on_iteration(runner, progress, phases=phases)
            learn(runner, start, todo, log_file)  # rsl-rl's per-iteration table goes to train.log
        if ranks.main:
            runner.save(str(run_dir / f"model_{cfg.iterations - 1}.pt"))
    wall = time.perf_counter() - t0
    steps = env.steps_total * ranks.world
    it_time = phases["collect"] + phases["learn"]
    summary = {"iterations": cfg.iterations, "iterations_this_session": todo, "wall_s_this_session": wall,
               "env_steps_this_session": steps, "failed_episodes": env.failed_total,
               "diverged": env.diverged_total, "episodes": env.episodes_total,
               "env_steps_per_s": steps / env.step_seconds if env.step_seconds else None,
               "training_steps_per_s": steps / it_time if it_time else None,
               "collect_s_per_iteration": phases["collect"] / todo if todo else None,
               "learn_s_per_iteration": phases["learn"] / todo if todo else None,
               "processes": ranks.world, "device": str(env.device)}
    if ranks.main:
        actor = runner.alg.get_policy()
        obs = torch.zeros(2, actor.obs_dim)  # a batch of 2: torch.export specialises a size-1 axis to the constant 1
        save_program(actor.as_jit().cpu().eval(), (obs,), ({0: torch.export.Dim("batch", min=1)},),
                     run_dir / "policy.pt", {"kind": "skill"})
        run.write_summary(summary)
    return summary


def finished_skill(cfg: SkillPPOConfig, run_dir, task: dict, worlds: int, *, init: str | Path | None = None,
                   meta: dict | None = None) -> dict | None:
    """The stored summary of the skill run ``run_dir`` where :func:`train_skill` would have nothing to do, checked
    without an environment: its latest checkpoint is ``model_<cfg.iterations - 1>.pt``, its ``policy.pt`` and a
    ``train_summary.json`` of ``cfg.iterations`` are there, and its ``config.json`` passes the resume check
    (another configuration is refused as :func:`train_skill` refuses it); ``None``: a run to train (fresh, cut
    short, extended or with its export missing).

    Args:
        cfg, init, meta: As for :func:`train_skill`.
        task: The task's record (:attr:`~wresdyn.skills.env.TrackingEnv.cfg_dict`, ``asdict`` of the task config).
        worlds: This process's worlds (the ``env.num_envs`` :func:`train_skill` would see: under torchrun its share).

    Under torchrun every rank reads the folder once rank 0 has written the skills before and before it writes this
    one, so all take the same decision.
    """
    return _checked(Path(run_dir), cfg, task, worlds, init, meta)[2]


def _checked(run_dir: Path, cfg: SkillPPOConfig, task: dict, worlds: int, init, meta):
    """The run folder of a skill, its latest checkpoint (``None``: none) and, where it has already trained
    ``cfg.iterations``, its stored summary (:func:`finished_skill`); a changed configuration is refused."""
    ranks = Ranks.from_env()
    record = {"ppo": asdict(cfg), "task": task, "num_worlds": worlds * ranks.world,
              "init": None if init is None else str(Path(init).resolve()), **(meta or {})}
    run = UpgradingRunnerFolder(run_dir, record, RESUME_MAY_CHANGE, writer="the skills' PPO", upgrade=upgrade_record)
    _all_ranks_here(ranks)  # rank 0 has written the last skill it trained (its export follows the last collective)
    ckpt = latest_checkpoint(run_dir)
    run.check(ckpt)
    done = _stored_summary(run_dir, ckpt, cfg.iterations)
    _all_ranks_here(ranks)  # rank 0 may write the folder once past here (a resumed export): every rank has read it
    return run, ckpt, done


def _all_ranks_here(ranks: Ranks) -> None:
    """Wait for every torchrun process where their process group is up (a first skill's is not, until its runner
    starts it: nothing of this launch has been written yet)."""
    if ranks.world > 1 and torch.distributed.is_initialized():
        torch.distributed.barrier()


def _stored_summary(run_dir: Path, ckpt: Path | None, iterations: int) -> dict | None:
    """The ``train_summary.json`` of a run that has trained ``iterations`` and exported its policy, else ``None``."""
    if ckpt is None or ckpt.name != f"model_{iterations - 1}.pt" or not (run_dir / "policy.pt").is_file():
        return None
    try:
        summary = json.loads((run_dir / "train_summary.json").read_text())
    except (OSError, ValueError):  # never written (killed before) or cut short
        return None
    return summary if isinstance(summary, dict) and summary.get("iterations") == iterations else None


def _start_from(runner, init, restart_std: float | None) -> None:
    """Load the last checkpoint of the skill run ``init`` into ``runner`` (actor, critic, optimiser) to fine-tune it
    from iteration 0, its action noise reset to ``restart_std`` (``None``: kept)."""
    base = latest_checkpoint(init)
    if base is None:
        raise FileNotFoundError(f"{init}: no checkpoint to fine-tune from")
    runner.load(str(base), map_location=str(runner.env.device))
    runner.current_learning_iteration = 0
    if restart_std is not None:
        _set_std(runner.alg.actor, restart_std)


def load_skill(run_dir) -> torch.nn.Module:
    """The trained skill of a run: ``policy(obs (N, 6n)) -> action (N, n)`` (the exported program, CPU)."""
    path = Path(run_dir) / "policy.pt"
    if not path.is_file():
        raise FileNotFoundError(f"{run_dir}: no policy.pt; train the skill first")
    return load_program(path)[0].module()
