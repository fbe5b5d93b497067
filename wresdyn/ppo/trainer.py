"""PPO for the residual (paper Sec. II-B) through rsl-rl's ``OnPolicyRunner``.

A run folder holds everything: ``config.json`` (the :class:`~wresdyn.ppo.ppo_config.TrainConfig`), rsl-rl
checkpoints ``model_<it>.pt`` (resumed from automatically after a kill), tensorboard event files, ``best.pt``
(:class:`BestOnValidation`: the actor with the lowest validation error so far and the validation curve), and at the
end the deterministic residual exported through ``torch.export`` (``policy.pt``, :mod:`wresdyn.learn.network_file`)
and ONNX (``policy.onnx``) with its metadata (``residual.json``; read back by
:func:`wresdyn.learn.run_residual.load_policy`), plus ``train_summary.json`` (env-steps/s, s per iteration, the
selected iteration) and ``train.log``: rsl-rl's networks and per-iteration tables (kept off the terminal, where a
progress bar stands per iteration, :func:`~wresdyn.ppo.runner.on_iteration`) and, from
``wresdyn train``, every line the command printed.

Model selection is made on the dataset's validation split: every ``ppo.select_every`` iterations the current
residual replays the validation trajectories open loop (:class:`wresdyn.learn.selection.ValidationScore`), and
the residual with the lowest error is the one exported. Held-out and OOD data are never read in training.

A resume is refused, naming the fields, when the configuration or the training data differ from what the folder
(a :class:`~wresdyn.learn.runs.RunnerFolder`) was started with (:data:`~wresdyn.ppo.ppo_config.RESUME_MAY_CHANGE`
may differ), and checkpoints are read as weights only (:class:`~wresdyn.ppo.runner.Runner`).
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from ..learn.residual import actor_critic_cfg, export_run_files, obs_stats, policy_from_actor
from ..learn.runs import RunError, RunnerFolder, check_resume, load_checkpoint, save_checkpoint
from ..learn.selection import ValidationScore
from ..progress import bar
from ..sim.physics import PhysicalParams
from .affinity import pin_process
from .ppo_config import DATASET_IDENTITY, RESUME_MAY_CHANGE, TrainConfig, upgrade_config_dict
from .replay_env import ReplayEnv
from .runner import (Ranks, Runner, UpgradingRunnerFolder, latest_checkpoint, learn, make_runner, on_iteration,
                     resume_runner, rsl_runner_cfg, seed_processes)

__all__ = ["train", "export", "runner_cfg", "BestOnValidation", "RunError"]


def train(dataset, robot, cfg: TrainConfig, run_dir: str | Path, resume: bool = True,
          data_path: str | Path | None = None, stop_below: float | None = None, log=print,
          physics: PhysicalParams | None = None) -> dict:
    """Train a residual with PPO on the ``train`` split of ``dataset``; resume from the latest checkpoint.

    Args:
        dataset: A :class:`wresdyn.data.dataset.Dataset` (only ``q``, ``qd``, ``qdd``, ``q_cmd`` are read).
        robot: The nominal robot the simulator uses.
        cfg: The run configuration; must equal the saved one when resuming, except
            :data:`~wresdyn.ppo.ppo_config.RESUME_MAY_CHANGE`.
        run_dir: Run folder (created).
        resume: Continue from ``model_<it>.pt`` in ``run_dir``; with ``False`` an existing checkpoint is an error.
        data_path: Where ``dataset`` was read from, recorded in ``config.json`` for ``wresdyn eval``.
        stop_below: Stop at the first validation check whose error is at or below this [rad] (time to fidelity,
            ``benchmarks/speed/time_to_fidelity.py``); the run is then exported as if it had ended there.
        log: Printer of the run's lines; a :class:`wresdyn.progress.Log` also draws a bar over the iterations.
        physics: The identified physics the residual is learned on (the hybrid; ``cfg.env.physics`` records where
            they came from), or ``None``: the robot file's values, no delay.

    Under ``torchrun`` (``WORLD_SIZE`` > 1) each process trains ``env.num_worlds / WORLD_SIZE`` worlds on its device
    (``cuda:<LOCAL_RANK>``, or the CPU over gloo) with seed ``seed + RANK``, and rsl-rl averages the gradients
    across processes; rank 0 alone writes the run folder and selects on validation, and every rank resumes from
    the same checkpoint.

    Returns:
        The training summary written to ``train_summary.json``.

    Raises:
        RunError: The run folder holds another configuration, other data
            (:data:`~wresdyn.ppo.ppo_config.DATASET_IDENTITY`) or a checkpoint that is not a weights-only rsl-rl
            checkpoint of these networks.
    """
    run_dir, ranks = Path(run_dir), Ranks.from_env()
    run = UpgradingRunnerFolder(run_dir, _run_record(dataset, robot, cfg, ranks, data_path),
                                [f"ppo.{k}" for k in RESUME_MAY_CHANGE], key="config", writer="`wresdyn train`",
                                upgrade=lambda record: {**record, "config": upgrade_config_dict(record["config"])})
    ckpt = _checkpoint_to_resume(run, resume)
    session = _start(dataset, robot, cfg, run_dir, ranks, log, physics)
    start = resume_runner(session.runner, ckpt, run_dir, log) if ckpt is not None else 0
    if ranks.main:  # written once the checkpoint has loaded: a refused resume leaves the folder as it was
        run.write_config()
    score = _validation_score(dataset, robot, cfg, session)
    best = BestOnValidation(run_dir / "best.pt", resumed=start > 0)
    done, reached, wall = _learn_and_select(session, cfg, score, best, start, stop_below, log)
    summary = _summary(session, cfg, best, done - start, wall, reached)
    if ranks.main:
        _write_results(session, cfg, best, summary, dataset, run)
    ranks.close()
    return summary


class BestOnValidation:
    """``best.pt``: the actor with the lowest validation error so far, and the validation curve (every check).

    Rewritten after each check (weights only, atomically); a resumed run reads it back, so its curve goes on and its
    earlier best still competes. ``best`` is the record, ``{"actor": state_dict, "meta": {"iteration",
    "validation", "validation_curve"}}``, or ``None`` before the first check."""

    def __init__(self, path: Path, resumed: bool) -> None:
        self.path = Path(path)
        self.best = load_checkpoint(self.path, keys=("actor", "meta")) if resumed and self.path.is_file() else None
        self.curve: list[dict] = self.best["meta"]["validation_curve"] if self.best else []

    def record(self, iteration: int, value: float, diverged: int, actor, wall_s: float | None = None) -> None:
        """Add a check of ``actor`` (an rsl-rl actor module) at ``iteration`` to the curve, keep the actor if its
        validation error ``value`` [rad] is the lowest yet, and rewrite ``best.pt``; ``wall_s``: the training time
        it took to get there [s] (``None``: not recorded)."""
        point = {"iteration": iteration, "validation": value, "diverged": diverged}
        if wall_s is not None:
            point["wall_s"] = wall_s
        self.curve.append(point)
        if self.best is None or value < self.best["meta"]["validation"]:
            weights = {k: v.detach().cpu().clone() for k, v in actor.state_dict().items()}
            self.best = {"actor": weights, "meta": {"iteration": iteration, "validation": value}}
        self.best["meta"]["validation_curve"] = self.curve
        save_checkpoint(self.best, self.path)


@dataclass
class _Session:
    """What this process trains with: its replay worlds, the rsl-rl runner, the observation normalisation."""

    env: ReplayEnv
    runner: Runner
    mean: np.ndarray
    std: np.ndarray
    ranks: Ranks
    log_file: Path | None
    """rsl-rl's tables go here (the run's ``train.log``; ``None`` on the ranks that write nothing)."""
    phases: dict = field(default_factory=lambda: {"collect": 0.0, "learn": 0.0})
    """rsl-rl's own split of the session's iterations: collection and update time [s]."""

    def policy(self, cfg: TrainConfig):
        """The current actor as the deterministic residual (:func:`~wresdyn.learn.residual.policy_from_actor`)."""
        return policy_from_actor(self.runner.alg.get_policy(), self.mean, self.std, self.env.scale.cpu().numpy(),
                                 cfg.residual.kind, cfg.residual.action_gain)


def runner_cfg(cfg: TrainConfig, run_name: str = "") -> dict:
    """The rsl-rl ``OnPolicyRunner`` configuration dict of a residual run."""
    actor, critic = actor_critic_cfg(cfg.residual)
    p = cfg.ppo
    return rsl_runner_cfg(
        num_steps_per_env=p.num_steps_per_env, save_interval=p.save_interval, actor=actor, critic=critic,
        run_name=run_name, num_learning_epochs=p.num_learning_epochs, num_mini_batches=p.num_mini_batches,
        clip_param=p.clip_param, gamma=p.gamma, lam=p.lam, value_loss_coef=p.value_loss_coef,
        entropy_coef=p.entropy_coef, learning_rate=p.learning_rate, max_grad_norm=p.max_grad_norm,
        desired_kl=p.desired_kl, use_mixed_precision=p.mixed_precision, one_sync_update=p.one_sync_update,
        packed_update=True, graph_update=p.graph_update is not False, compile_mode=p.compile_mode,
        deferred_episode_log=p.defers_episode_log())


def _run_record(dataset, robot, cfg: TrainConfig, ranks: Ranks, data_path) -> dict:
    """What ``config.json`` records of the run (configuration, data identity, data path), once the data and the
    processes are checked to fit: worlds that split over the ranks, training trajectories, the robot's joints."""
    ranks.num_worlds(cfg.env.num_worlds)
    if not dataset.split("train"):
        raise RunError("the dataset has no 'train' trajectories")
    if list(dataset.joint_names) != list(robot.joint_names):
        raise RunError(f"dataset joints {list(dataset.joint_names)[:3]}... do not match the robot's "
                       f"{list(robot.joint_names)[:3]}...")
    info = {"robot_file": str(getattr(dataset, "robot_file", "")), "robot_sha256": getattr(dataset, "robot_sha256", ""),
            "rate_hz": float(dataset.rate_hz), "joint_names": list(dataset.joint_names),
            "train": [t.name for t in dataset.split("train")]}
    path = None if data_path is None else str(Path(data_path).resolve())
    return {"config": asdict(cfg), "dataset": info, "data_path": path}


def _checkpoint_to_resume(run: RunnerFolder, resume: bool) -> Path | None:
    """The checkpoint to continue from, if any; refused (naming what changed) when the folder was started with
    another configuration (a run may be extended, or moved to another device or machine: ``RESUME_MAY_CHANGE``) or
    other data, or when ``resume`` is false."""
    ckpt = latest_checkpoint(run.path)
    if ckpt is not None and not resume:
        raise RunError(f"{run.path} already holds checkpoints ({ckpt.name}); resume it or choose another folder")
    old = run.check(ckpt)
    if old is None:
        return None
    # a run folder may hold only some of the identity fields (the others unrecorded): compare those it has
    old_data = old.get("dataset") or {}
    keys = [k for k in DATASET_IDENTITY if k in old_data]
    check_resume(run.path, {"dataset": {k: old_data[k] for k in keys}},
                 {"dataset": {k: run.record["dataset"][k] for k in keys}}, what="data")
    return ckpt


def _start(dataset, robot, cfg: TrainConfig, run_dir: Path, ranks: Ranks, log, physics) -> _Session:
    """Seed this process (``seed + RANK``), build its replay worlds and the runner (rsl-rl prints the networks
    into ``train.log``); rank 0 makes the run folder."""
    seed = cfg.ppo.seed + ranks.rank
    seed_processes(seed, cfg.ppo.torch_threads)
    if cfg.ppo.pin_cpus:
        pin_process(ranks.local_rank, ranks.world, cfg.ppo.device)
    train_trajs = dataset.split("train")
    num_worlds = ranks.num_worlds(cfg.env.num_worlds)
    mean, std = obs_stats(train_trajs)
    env = ReplayEnv(robot, train_trajs, dataset.rate_hz, num_worlds, cfg.env, cfg.residual, cfg.rewards,
                    device=ranks.device(cfg.ppo.device), seed=seed, obs_mean=mean, obs_std=std,
                    graph=cfg.ppo.cuda_graph, weights=dataset.fit_weights(), physics=physics)
    if ranks.main:
        run_dir.mkdir(parents=True, exist_ok=True)
    log(f"{num_worlds} replay worlds on {env.device}, {type(env.sim.solver).__name__}")  # writes the waiting lines too
    rcfg = runner_cfg(cfg, run_dir.name)
    rcfg["check_for_nan"] = not env.graph  # a graph-replayed step is not checked per step (a host sync each)
    runner = make_runner(env, rcfg, run_dir, ranks.main)
    return _Session(env, runner, mean, std, ranks, run_dir / "train.log" if ranks.main else None)


def _validation_score(dataset, robot, cfg: TrainConfig, session: _Session) -> ValidationScore | None:
    """The score on the validation split (on rank 0; ``None`` elsewhere, or without validation trajectories)."""
    validation = dataset.split("validation") if session.ranks.main else []
    if not validation:
        return None
    return ValidationScore(robot, validation, dataset.rate_hz, cfg.env.solver, session.ranks.device(cfg.ppo.device),
                           physics=session.env.physics, weights=dataset.fit_weights(),
                           friction_kappa=cfg.env.friction_kappa)


def _learn_and_select(session: _Session, cfg: TrainConfig, score, best: BestOnValidation, start: int,
                      stop_below: float | None, log) -> tuple[int, int | None, float]:
    """Learn from iteration ``start`` to ``ppo.iterations``, scoring on validation every ``ppo.select_every``
    (recorded in ``best``) and stopping early at ``stop_below``: ``(iterations done, the one that reached
    stop_below or None, training time without the scoring [s])``. rsl-rl's collect and learn times per iteration
    accumulate in ``session.phases``."""
    every = cfg.ppo.select_every or max(1, cfg.ppo.iterations // 10)
    if score is not None and start == 0 and session.env.physics is not None:
        # on identified physics (the hybrid) the near-zero residual at the start is a candidate too: the hybrid is
        # never selected worse than the identified model alone
        value = score(session.policy(cfg))
        log(f"validation at the start: {value:.4f} rad")
        best.record(0, value, score.last_diverged, session.runner.alg.get_policy())

    progress = bar(log, cfg.ppo.iterations, "train", start)
    on_iteration(session.runner, progress, phases=session.phases)
    t0, eval_s, done, reached = time.perf_counter(), 0.0, start, None
    with progress:
        while done < cfg.ppo.iterations and reached is None:
            # learn up to the next selection point
            n = min(every - done % every, cfg.ppo.iterations - done)
            learn(session.runner, done, n, session.log_file)
            done += n
            if score is not None:
                t_eval = time.perf_counter()
                value = score(session.policy(cfg))
                log(f"validation after {done} iterations: {value:.4f} rad")
                if stop_below is not None and value <= stop_below:
                    reached = done
                best.record(done, value, score.last_diverged, session.runner.alg.get_policy(),
                            wall_s=t_eval - t0 - eval_s)
                eval_s += time.perf_counter() - t_eval
            if session.ranks.world > 1 and stop_below is not None:
                reached = _stop_where_rank0_stopped(reached, session.env.device)
    return done, reached, time.perf_counter() - t0 - eval_s


def _stop_where_rank0_stopped(reached: int | None, device) -> int | None:
    """Under torchrun, every rank stops at the iteration where rank 0 (the one that scores) reached the target."""
    import torch

    flag = torch.tensor([-1 if reached is None else reached], device=device)
    torch.distributed.broadcast(flag, src=0)
    return None if int(flag) < 0 else int(flag)


def _summary(session: _Session, cfg: TrainConfig, best: BestOnValidation, todo: int, wall: float,
             reached: int | None) -> dict:
    """What ``train_summary.json`` says of the session: speeds, divergences, where it ran, the selection."""
    env, phases = session.env, session.phases
    it_time = session.runner.logger.tot_time  # collection + update, without start-up
    steps = env.steps_total * session.ranks.world  # every rank steps as many worlds
    return {
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
        "processes": session.ranks.world,
        "cuda_graph": env.graph,
        "stopped_at_target": reached,
        "solver": type(env.sim.solver).__name__,
        "selected_iteration": best.best["meta"]["iteration"] if best.best else cfg.ppo.iterations,
        "selected_validation": best.best["meta"]["validation"] if best.best else None,
        "validation_curve": best.curve,
    }


def _write_results(session: _Session, cfg: TrainConfig, best: BestOnValidation, summary: dict, dataset,
                   run: RunnerFolder) -> None:
    """Export the residual selected on validation (the last one without validation), the physics it was trained
    on (the hybrid's, for evaluation to replay with) and ``train_summary.json``."""
    actor = session.runner.alg.get_policy()
    if best.best is not None:
        # into the actor itself: training is over and its last checkpoint written, and a deepcopy of it fails on
        # the non-leaf outputs its distribution keeps from the last update
        actor.load_state_dict(best.best["actor"])
    export(actor, run.path, cfg, session.mean, session.std, session.env.scale.cpu().numpy(), dataset)
    if session.env.physics is not None:
        session.env.physics.save(run.path / "physics.json")
    run.write_summary(summary)


def export(actor, run_dir: Path, cfg: TrainConfig, mean, std, scale, dataset) -> None:
    """Write ``policy.pt`` (a ``torch.export`` archive), ``policy.onnx`` and ``residual.json`` for a trained actor."""
    policy = policy_from_actor(actor, mean, std, scale, cfg.residual.kind, cfg.residual.action_gain)
    export_run_files(policy, run_dir, dataset, arch=cfg.residual.arch, action_gain=cfg.residual.action_gain)

