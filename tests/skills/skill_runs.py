"""What the skills' tests share: the sample rate, a quiet real robot and `wresdyn fit` run folders from the real
writers."""

from __future__ import annotations

import dataclasses
import shutil

import numpy as np

RATE = 500.0
"""Sample rate of every skill test [Hz]."""


def quiet_real(robot, mismatch):
    """The real robot of ``mismatch`` without sensor noise (exact comparisons), on its stand or, for a floating
    ``robot``, on its floor."""
    from wresdyn.data.real_robot import RealRobot

    mm = dataclasses.replace(mismatch, position_noise=0.0, velocity_noise=0.0, encoder_resolution=0.0,
                             velocity_resolution=0.0)
    return RealRobot(robot, mm, RATE)


_FIT_RUNS: dict[tuple, tuple] = {}
"""The run folders :func:`fit_run` wrote in this process, by robot, dataset, kind and physics: each later call copies
one (its writers, a ``torch.export`` archive and an ONNX export, take seconds; every test only reads its run). The
robot and the dataset are kept with it, so that their ids are not reused."""


def fit_run(tmp_path, robot, data, kind: str, physics: bool):
    """A `wresdyn fit` run folder from the real writers: a (tiny, untrained) residual, identified physics or not;
    the same folder's copy for the same robot, data, kind and physics within a process."""
    from wresdyn.fit.gradfit import build_policy
    from wresdyn.learn.residual import ResidualConfig, export_run_files, obs_stats
    from wresdyn.sim.physics import PhysicalParams

    run = tmp_path / kind
    key = (id(robot), id(data), kind, physics)
    if key in _FIT_RUNS:
        shutil.copytree(_FIT_RUNS[key][0], run)
        return run
    source = tmp_path / f".{kind}_written"  # kept as written: the copies come from here
    source.mkdir()
    if physics:
        p = PhysicalParams.nominal(robot)
        p.kp *= 0.8
        p.delay = np.full(robot.n_dof, 0.004)
        p.save(source / "physics.json")
    mean, std = obs_stats(data.split("train"))
    export_run_files(build_policy(robot, ResidualConfig(kind=kind, fraction=0.1), mean, std), source, data, arch="mlp",
                     learner="gradient")
    _FIT_RUNS[key] = (source, robot, data)
    shutil.copytree(source, run)
    return run
