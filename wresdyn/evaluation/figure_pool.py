"""Figures drawn in processes of their own, beside the replays that produce their data.

Drawing an evaluation's figures is host work of a few seconds (importing matplotlib, laying out and rasterising
each figure) that shares nothing with the replays but their results. :class:`FigurePool` draws them in spawned
worker processes, started and importing matplotlib while the replays run, so the figures cost the command about
the longest one instead of their sum, and the command's own interpreter never imports matplotlib. A figure is
drawn by the same function on the same data, so the files are the same bytes as when drawn in this process.
"""

from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from types import SimpleNamespace

__all__ = ["FigurePool", "default_workers", "light_runs", "light_robot"]

MAX_WORKERS = 4
"""At most one process per figure of an evaluation (three splits and the learning curves)."""


def default_workers() -> int:
    """One worker per core this process may run on, less the one the replays keep busy, at most
    :data:`MAX_WORKERS`, at least one."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(MAX_WORKERS, cores - 1))


def _ready() -> None:
    """Worker start: import the plotting modules, so that the first figure does not wait for them."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401

    from . import plots  # noqa: F401


def light_robot(robot) -> SimpleNamespace:
    """What a figure reads of a robot (its joint names): pickled to a worker instead of the robot and its model."""
    return SimpleNamespace(joint_names=list(robot.joint_names))


def light_runs(runs: dict) -> dict:
    """What :func:`~.plots.plot_fig3` reads of a split's replays (the first trajectory's positions), as plain
    objects: the worker then needs neither the simulator's modules nor the other trajectories."""
    return {name: SimpleNamespace(q=[r.q[0]]) for name, r in runs.items()}


class FigurePool:
    """Figures submitted here are drawn by worker processes (spawned, so that no thread or device state of this
    process is copied); :meth:`wait` returns once every file is written and raises the first figure's error. Where
    no process can be started the figures are drawn here, one after the other, as before.

    Args:
        workers: Processes to start at once (default :func:`default_workers`); each imports matplotlib at its
            start.
    """

    def __init__(self, workers: int | None = None) -> None:
        n = max(1, workers or default_workers())
        self._jobs: list[Future] = []
        try:
            self._pool = ProcessPoolExecutor(n, mp_context=mp.get_context("spawn"), initializer=_ready)
            # processes start on demand: one warm-up job each starts them all now, while the caller replays
            self._jobs += [self._pool.submit(int) for _ in range(n)]
        except (OSError, RuntimeError):
            self._pool = None

    def submit(self, fn, *args, **kwargs) -> None:
        """Draw ``fn(*args, **kwargs)`` (a module-level function, its arguments picklable) in a worker."""
        if self._pool is not None:
            try:
                self._jobs.append(self._pool.submit(fn, *args, **kwargs))
                return
            except (BrokenProcessPool, RuntimeError):
                self._pool = None
        fn(*args, **kwargs)

    def wait(self) -> None:
        """Wait for every figure; raise the first error a figure raised."""
        try:
            for job in self._jobs:
                job.result()
        finally:
            self._jobs = []
            if self._pool is not None:
                self._pool.shutdown()
                self._pool = None

    def __enter__(self) -> "FigurePool":
        return self

    def __exit__(self, *exc) -> None:
        if exc[0] is None:
            self.wait()
        elif self._pool is not None:  # the caller's error wins; the figures drawn so far are left as they are
            self._pool.shutdown(cancel_futures=True)
            self._pool = None
