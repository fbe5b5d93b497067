"""Load a dataset together with the robot it is replayed on."""

from __future__ import annotations

__all__ = ["load_data", "dataset_robot"]


def load_data(data: str, robot_file: str | None = None):
    """The dataset and the robot to replay it on (see :func:`dataset_robot`), with the dataset's columns in the
    robot's joint order."""
    from .dataset import load_dataset

    ds = load_dataset(data)
    robot = dataset_robot(ds.robot_file, robot_file)
    return ds.for_robot(robot, str(data)), robot


def dataset_robot(recorded: str, robot_file: str | None = None, gains=None):
    """The robot of a dataset: ``robot_file``, or the one it was recorded on (its header's ``robot_file``,
    ``recorded``) looked up relative to the working directory, then to the repository; ``gains`` as in
    :func:`~wresdyn.robot.description.load_robot`."""
    from pathlib import Path

    from ..paths import REPO
    from ..robot.description import load_robot

    path = robot_file or recorded
    if robot_file is None and not Path(path).is_absolute() and not Path(path).exists():
        repo_path = REPO / path
        path = repo_path if repo_path.exists() else path
    return load_robot(path, gains=gains)
