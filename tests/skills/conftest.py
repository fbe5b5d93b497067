"""Fixtures of the floor tests."""

import pytest


@pytest.fixture(scope="module")
def floating(humanoid):
    """The humanoid with a floating base (the floor plants' robot)."""
    from wresdyn.robot.description import load_robot

    return load_robot(humanoid.source, base="floating")
