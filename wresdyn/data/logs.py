"""Import real-robot logs of any format into :class:`~wresdyn.data.dataset.Trajectory` on the simulation step.

A log is a CSV or NPZ file (:mod:`wresdyn.data.log_files`, which also maps its joints and resamples it), an MCAP
file of ROS 2 messages (:mod:`wresdyn.data.mcap_logs`) or a SAGE run (:mod:`wresdyn.data.importers`, which also
reads LeRobot datasets and assigns the runs of many logs to splits).
Column conventions and the mapping file: docs/dataset.md.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .dataset import Dataset, Trajectory
from .importers import SplitRule, import_runs, read_sage, sage_run
from .log_files import IDENTITY, LogMap, read_file
from .log_resample import log_stats, resample, to_trajectory
from .mcap_logs import McapTopics, is_mcap, read_mcap

__all__ = ["LogMap", "read_log", "resample", "log_stats", "import_log", "import_logs"]


def read_log(path, joint_names: list[str], log_map: LogMap | None = None, topics: McapTopics | None = None
             ) -> dict[str, np.ndarray | None]:
    """Read one log into arrays in ``joint_names`` order, at the log's own time stamps: a CSV or NPZ file
    (:func:`~wresdyn.data.log_files.read_file`), an MCAP file (``topics``; :func:`~wresdyn.data.mcap_logs.read_mcap`)
    or a SAGE run (its folder, ``control.csv`` or ``state_motor.csv``; :func:`~wresdyn.data.importers.read_sage`).

    Returns:
        ``{"t": (N,) [s], "q": (N, n) [rad], "qd": (N, n) [rad/s] or None, "q_cmd": (N, n) [rad],
        "tau": (N, n) [N*m] or None}``; a SAGE run or an MCAP file adds ``"t_cmd": (M,) [s]``, the commands' own
        stamps, and then ``q_cmd`` has shape (M, n).
    """
    log_map = log_map or IDENTITY
    if is_mcap(path):
        return read_mcap(path, joint_names, log_map, topics)[0]
    run = sage_run(path)
    if run is not None:
        return read_sage(run, joint_names, log_map)
    return read_file(path, joint_names, log_map)


def import_log(path, robot, rate_hz: float = 500.0, split: str = "heldout", name: str | None = None,
               log_map: LogMap | None = None, topics: McapTopics | None = None) -> Trajectory:
    """Read one log (CSV, NPZ, MCAP or a SAGE run) and resample it onto the simulation step. See docs/dataset.md."""
    log = read_log(path, list(robot.joint_names), log_map, topics)
    path = Path(path)
    run_name = path.name if path.is_dir() or path.suffix.lower() not in (".csv", ".npz", ".mcap") else path.stem
    if path.name in ("control.csv", "state_motor.csv") and "t_cmd" in log:
        run_name = path.parent.name
    return to_trajectory(log, rate_hz, name or run_name, split, str(path))


def import_logs(paths, robot, rate_hz: float = 500.0, split: str = "heldout", **kwargs) -> Dataset:
    """A :class:`~wresdyn.data.dataset.Dataset` of real logs (no mismatch, no seed), one trajectory per run, all in
    ``split``; any format :func:`wresdyn.data.importers.import_runs` reads (its keyword arguments pass through)."""
    return import_runs(paths, robot, rate_hz, splits=SplitRule(default=split), **kwargs)
