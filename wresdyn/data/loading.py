"""Load a dataset together with the robot it is replayed on."""

from __future__ import annotations

__all__ = ["load_data"]


def load_data(data: str, robot_file: str | None = None):
    """The dataset and the robot to replay it on (``robot_file`` or the dataset's own, looked up relative to the
    working directory, then to the repository), with the dataset's columns in the robot's joint order."""
    from pathlib import Path

    from ..paths import REPO
    from ..robot.description import load_robot
    from .dataset import load_dataset

    ds = load_dataset(data)
    path = robot_file or ds.robot_file
    if robot_file is None and not Path(path).is_absolute() and not Path(path).exists():
        repo_path = REPO / path
        path = repo_path if repo_path.exists() else path
    robot = load_robot(path)
    return ds.for_robot(robot, str(data)), robot

