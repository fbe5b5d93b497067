"""Figures drawn in worker processes (:mod:`wresdyn.evaluation.figure_pool`): the same bytes as drawn in this
process, errors raised where the caller waits, and the in-process fallback."""

import numpy as np
import pytest

from wresdyn.data.dataset import Trajectory
from wresdyn.evaluation import figure_pool
from wresdyn.evaluation.figure_pool import FigurePool, light_robot, light_runs
from wresdyn.evaluation.plots import plot_fig3
from wresdyn.sim.rollout import Replays


def _split(robot, rng):
    t = np.arange(200) / 100.0
    q = rng.standard_normal((200, robot.n_dof)).cumsum(0) * 1e-2
    traj = Trajectory("t0", "heldout", t, q, np.zeros_like(q), np.zeros_like(q), q)
    runs = {"pd": Replays([q + 0.01], [np.zeros_like(q)], [-1]), "residual": Replays([q + 0.002], [q], [-1])}
    return traj, runs


def test_a_figure_drawn_by_a_worker_is_the_same_file(robot, tmp_path):
    traj, runs = _split(robot, np.random.default_rng(0))
    here = plot_fig3(robot, traj, runs, tmp_path / "here.png", 100.0, title="heldout")
    with FigurePool(workers=1) as pool:
        pool.submit(plot_fig3, light_robot(robot), traj, light_runs(runs), tmp_path / "there.png", 100.0,
                    title="heldout")
    assert pool._pool is None  # shut down on leaving
    assert (tmp_path / "there.png").read_bytes() == here.read_bytes()


def _fail(path):
    raise ValueError(f"cannot draw {path}")


def test_a_figure_error_is_raised_where_the_caller_waits(tmp_path):
    pool = FigurePool(workers=1)
    pool.submit(_fail, tmp_path / "x.png")
    with pytest.raises(ValueError, match="cannot draw"):
        pool.wait()


def test_without_processes_the_figures_are_drawn_here(monkeypatch, tmp_path):
    def refuse(*a, **k):
        raise OSError("no processes here")

    monkeypatch.setattr(figure_pool, "ProcessPoolExecutor", refuse)
    drawn = []
    with FigurePool() as pool:
        pool.submit(drawn.append, "fig")
        assert drawn == ["fig"]
