"""The window-fit loop shared by identification (:mod:`wresdyn.identify.sysid`) and the gradient fit of a residual (:mod:`wresdyn.fit.gradfit`).

Both fit by multiple shooting: each iteration replays B windows of H recorded steps from their recorded start state
and descends the mismatch. What they share lives here, as rsl_rl splits its runner from the algorithm: the
schedule (:mod:`.schedule`: the horizon curriculum and the learning rate, for a fixed count or until validation
plateaus), the run folder (:class:`~wresdyn.learn.runs.RunFolder`: resume, checkpoints, the curve), scoring
on the validation split (the wall-clock counts training only), the log lines and checkpoints, the stops (the
schedule's, ``until``, ``stop_below``) and the final selection of the best iterate on validation. A learner (:class:`WindowLearner`) keeps its model, its loss and its step, with whatever
it does at given iterations.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from typing import Protocol

import numpy as np
import torch

from ..progress import bar
from .runs import RunFolder
from .schedule import FixedSchedule, make_schedule

__all__ = ["WindowLearner", "run_window_fit", "schedule", "start_window_fit",
           "joint_weights", "squared_error"]


class WindowLearner(Protocol):
    """What :func:`run_window_fit` drives: a model, its optimiser and its loss on windows."""

    name: str
    """What the progress bar calls the loop (``"fit"``, ``"identify"``)."""
    what: str
    """What a message calls the learner (``"gradient fit"``)."""
    module: torch.nn.Module
    """What is selected: its ``state_dict`` is kept at each new best on validation and restored at the end."""
    horizons: tuple[int, ...]
    """Window lengths [steps] in equal parts of training."""
    parts: tuple[str, ...]
    """Names of the loss parts a deferred step returns as one device tensor, the loss first."""
    deferred: bool
    """Whether :meth:`step` returns its loss parts without waiting for the device (read back at log, validation
    and checkpoint times, and for the first two iterations of a session)."""
    checkpoint_keys: tuple[str, ...]
    """The learner's entries in a checkpoint (its :meth:`state`)."""
    map_location: str
    """Where a resumed checkpoint's tensors are loaded (``torch.load``'s ``map_location``)."""

    def begin(self, run: RunFolder) -> None:
        """Before the first iteration of a fresh run: score the starting point as a candidate if it is one."""

    def step(self, it: int, h: int, lr: float) -> tuple[dict, torch.Tensor | None]:
        """One optimiser step at iteration ``it`` (from 0) on windows of ``h`` steps at learning rate ``lr``; returns
        the curve row's fields and, when :attr:`deferred`, the tensor of :attr:`parts` still on the device."""

    def score(self) -> float | None:
        """The current model's validation error [rad]; ``None`` without a validation split."""

    def state(self) -> dict:
        """The learner's checkpoint entries (weights, optimiser, generators): tensors and plain containers."""

    def meta(self) -> dict:
        """The learner's extra bookkeeping, stored in the checkpoint's ``meta``."""

    def restore(self, data: dict) -> None:
        """Take back :meth:`state` and :meth:`meta` (``data["meta"]``) from a checkpoint."""


def schedule(cfg, horizons, it: int) -> tuple[int, float]:
    """Window length [steps] and learning rate at iteration ``it`` of a fixed ``cfg.iterations``
    (:class:`~wresdyn.learn.schedule.FixedSchedule`)."""
    _, h, lr = FixedSchedule(cfg, horizons).at(it)
    return h, lr


def run_window_fit(cfg, learner: WindowLearner, run: RunFolder, rng: np.random.Generator, log=print,
                   until: int | None = None, stop_below: float | None = None) -> list[dict]:
    """Resume ``run`` if it holds a checkpoint, iterate ``learner`` until its schedule ends (or ``until``), and
    leave ``learner.module`` at the best iterate on validation when the schedule is done (or ``stop_below`` reached).

    Args:
        cfg: The learner's config: ``iterations`` (``None``: until validation plateaus, :mod:`.schedule`), ``lr``,
            ``lr_final``, ``select_every`` and the plateau rule's fields.
        learner: The model, its loss and its step; its optional ``on_stage(stage, it)`` is called where a horizon
            stage begins, its optional ``non_finite(it)`` makes the error raised for a non-finite loss (``it`` from 0).
        run: The run folder (``RunFolder(None, ...)`` keeps it in memory).
        rng: The window sampler, checkpointed with the run.
        log: Progress printer.
        until: Stop (and checkpoint) after this many iterations, to resume later; ``None``: the schedule's end.
        stop_below: End at the first validation score at or below this [rad], with the best selected so far.

    Returns:
        The learning curve (``run.curve``), also written to ``curve.json``.
    """
    sched = make_schedule(cfg, learner.horizons)
    data = run.resume(keys=learner.checkpoint_keys, map_location=learner.map_location)
    if data is not None:
        learner.restore(data)
        rng.bit_generator.state = data["meta"]["rng"]
        sched.restore(data["meta"].get("schedule", {}))
        log(f"resumed from {run.checkpoint} at iteration {run.iteration}")
    else:
        if getattr(log, "clock", False):  # a clocked log splits the learner's set-up from its first validation
            log(f"{learner.what}: set up; scoring the start")
        learner.begin(run)
    start_it, curve, best = run.iteration, run.curve, run.best
    t0 = time.perf_counter() - run.wall
    reached = False
    finished = False
    stage = None
    on_stage = getattr(learner, "on_stage", None)
    pending: list[tuple[dict, torch.Tensor]] = []  # rows whose loss parts are still on the device

    def settle() -> None:
        """Read the pending rows' loss parts from the device (one sync) and fail at the first non-finite loss."""
        if not pending:
            return
        values = torch.stack([p for _, p in pending]).tolist()
        for (row, _), v in zip(pending, values):
            row.update(zip(learner.parts, v))
            if not np.isfinite(row["loss"]):
                own = getattr(learner, "non_finite", None)  # a learner's own error (what to change), if it has one
                raise own(row["iteration"] - 1) if own else FloatingPointError(
                    f"{learner.what}: non-finite loss at iteration {row['iteration']} (simulation diverged)")
        pending.clear()

    def checkpoint() -> None:
        # written on a thread while training goes on (RunFolder.save), waited for before this function returns
        run.save(learner.state(), background=True, rng=rng.bit_generator.state, schedule=sched.state(),
                 **learner.meta())

    total = sched.total if until is None else min(until, sched.total)
    it = start_it
    with bar(log, total, learner.name, start_it) as progress, _flushed_on_error(run):
        while True:
            wall = curve[-1]["wall"] if curve else run.wall
            if sched.finished(it, wall):
                finished = True
                break
            if until is not None and it >= until:
                break
            s, h, lr = sched.at(it)
            if s != stage and on_stage is not None:
                on_stage(s, it)
            stage = s
            fields, parts = learner.step(it, h, lr)
            row = {"iteration": it + 1, "wall": time.perf_counter() - t0, **fields}
            if parts is not None:
                pending.append((row, parts))
            if not learner.deferred or it < start_it + 2:
                # eager: each iteration is checked before the next; deferred, the first two of a session (warm-up and
                # capture) wait for the device, so their rows' wall-clock is exact (a reference for throughput)
                settle()
                row["wall"] = time.perf_counter() - t0
            validate = sched.validate_now(it)
            last = it + 1 == total
            report = sched.log_now(it) or last
            if validate or report:
                settle()
                row["wall"] = time.perf_counter() - t0  # the device has caught up: the row's true wall-clock
            note = ""
            if validate:
                t_eval = time.perf_counter()
                value = learner.score()
                t0 += time.perf_counter() - t_eval  # wall-clock counts training only
                if value is not None:
                    row["validation"] = value
                    best.consider(value, it + 1, learner.module)
                    reached = stop_below is not None and value <= stop_below
                kept = best.state is not None and best.iteration == 0  # the starting point, still selected
                note = sched.observe(value, it + 1, row["wall"], start=best.value if kept else None)
            curve.append(row)
            progress.update(1, f"H={h}" + (f"  loss {row['loss']:.2e}" if "loss" in row else ""))
            it += 1
            if report or reached:
                of = f"/{cfg.iterations}" if cfg.iterations is not None else ""
                msg = f"iter {it:5d}{of}  H={h:3d}  loss {row['loss']:.3e}  |dq|² {row['pos']:.3e}"
                log(msg + (f"  validation {row['validation']:.4f} rad" if "validation" in row else "")
                    + f"  {row['wall']:.0f}s")
                checkpoint()
            if note:
                log(note)
            if reached:
                log(f"validation {row['validation']:.4f} rad <= {stop_below:.4f} rad at iteration {it}: stopping")
                break
    settle()
    if finished:
        if curve and run.iteration != it:
            checkpoint()
        log(f"{learner.what}: {sched.reason}")
    run.flush()
    run.write_curve()
    if best.state is not None and (finished or reached):
        learner.module.load_state_dict(best.state)
        log(f"selected iteration {best.iteration} by validation ({best.value:.4f} rad)")
    return curve


@contextmanager
def _flushed_on_error(run: RunFolder):
    """Wait for a checkpoint still being written when the loop fails, keeping the loop's error (not the writer's)."""
    try:
        yield
    except BaseException:
        run.flush(check=False)
        raise


def start_window_fit(cfg, dataset):
    """Pin torch's threads, seed torch and the window sampler, and take the training split: ``(rng, train, dt)``
    with ``dt`` the sample period [s]."""
    if cfg.torch_threads is not None:
        torch.set_num_threads(cfg.torch_threads)
    torch.manual_seed(cfg.seed)
    train = dataset.split("train")
    if not train:
        raise ValueError("the dataset has no training trajectories")
    return np.random.default_rng(cfg.seed), train, 1.0 / dataset.rate_hz


def joint_weights(dataset, device):
    """The dataset's per-joint fit weights (:meth:`~wresdyn.data.dataset.Dataset.fit_weights`: 0 for a joint
    excluded from fitting) as a float32 tensor (n,) on ``device``, or ``None`` when every joint is fitted (the losses
    then skip the weighting)."""
    if not dataset.excluded_joints:
        return None
    return torch.as_tensor(dataset.fit_weights(), dtype=torch.float32, device=device)


def squared_error(x, ref, weights=None):
    """Window-fit error term: Σ_j w_j (x_j − ref_j)² over the joints (last axis), mean over everything else.
    ``x``, ``ref`` (..., n); ``weights`` (n,) or ``None`` (all 1)."""
    sq = (x - ref) ** 2
    return (sq if weights is None else sq * weights).sum(-1).mean()
