"""Shared fixtures: robots loaded once per test session."""

import pytest

QUADRUPED_GAINS = {"joint": [{"match": "*", "kp": 80.0, "kd": 2.0, "armature": 0.02}]}
"""Gains for newton's quadruped.urdf, which has none (same as examples/gains/quadruped.toml, inline)."""


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", help="also run tests marked slow")


def pytest_collection_modifyitems(config, items):
    if config.getoption("--run-slow"):
        return
    skip = pytest.mark.skip(reason="slow: opt in with --run-slow")
    for item in items:
        if "slow" in item.keywords:
            item.add_marker(skip)


@pytest.fixture(scope="session")
def humanoid():
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    return load_robot(DEFAULT_ROBOT)


@pytest.fixture(scope="session")
def robot(humanoid):
    """The robot of the learner tests (replay env, PPO, evaluation): the project humanoid."""
    return humanoid


@pytest.fixture(scope="session")
def data(humanoid):
    """A tiny recording of the humanoid: 2 train, 1 held-out, 1 OOD trajectory of 0.1 s (tests/_tiny_data.py)."""
    from _tiny_data import make_dataset

    return make_dataset(humanoid, seconds=0.1, counts=(2, 1, 1))


@pytest.fixture(scope="session")
def quadruped():
    from wresdyn.robot.description import load_robot

    return load_robot("newton:quadruped.urdf", gains=QUADRUPED_GAINS)
