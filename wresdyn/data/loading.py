"""Load a dataset together with the robot it is replayed on: the robot file it was recorded on and the gains
config stored with it, so ``fit``, ``train``, ``identify`` and ``eval`` replay on the robot ``collect`` used."""

from __future__ import annotations

import warnings

from ..paths import REPO
from ..robot.description import load_robot
from .dataset import load_dataset

__all__ = ["load_data", "dataset_robot"]


def load_data(data: str, robot_file: str | None = None, gains=None):
    """The dataset and the robot to replay it on, with the dataset's columns in the robot's joint order.

    Args:
        data: Dataset file (``.npz``).
        robot_file: Robot file to replay on; default: the one the dataset was recorded on (:func:`dataset_robot`).
        gains: Gains config (TOML path or parsed dict) to load the robot with. It **replaces** the gains config
            stored in the dataset (a warning says so when the dataset has one); default: the stored one, so the
            robot is the one the data was recorded on.

    Raises:
        RobotError: the robot has no PD gains or a placeholder effort limit (nothing to replay faithfully).
        DatasetError: the dataset cannot be read or does not match the robot's joints.
    """

    ds = load_dataset(data)
    if gains is not None and ds.gains is not None:
        stored = ds.gains.get("file") or "an inline config"
        warnings.warn(f"{data}: using the gains config {gains} instead of the one stored in the dataset ({stored})",
                      stacklevel=2)
    robot = dataset_robot(ds.robot_file, robot_file, gains if gains is not None else ds.gains_config)
    robot.check_replay()
    return ds.for_robot(robot, str(data)), robot


def dataset_robot(recorded: str, robot_file: str | None = None, gains=None):
    """The robot of a dataset: ``robot_file``, or the one it was recorded on (its header's ``robot_file``,
    ``recorded``) looked up relative to the working directory, then to the repository; ``gains`` as in
    :func:`~wresdyn.robot.description.load_robot` (pass a dataset's stored ``Dataset.gains_config`` to get the
    robot it was recorded on)."""
    from pathlib import Path

    path = robot_file or recorded
    if robot_file is None and not Path(path).is_absolute() and not Path(path).exists():
        repo_path = REPO / path
        path = repo_path if repo_path.exists() else path
    return load_robot(path, gains=gains)
