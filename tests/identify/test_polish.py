"""The polish's coordinate handling (:mod:`wresdyn.identify.refine`), on the 5-link arm of the known-truth cases: a
robot with several moving links, whose link coordinates are not one contiguous tensor."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from wresdyn.identify.refine import _values
from wresdyn.robot.description import load_robot
from wresdyn.sim.physics import PhysicsModel

ARM = Path(__file__).resolve().parents[1] / "data" / "known_truth" / "arm5.xml"


def test_coordinates_round_trip_on_several_links():
    robot = load_robot(ARM, gains={"joint": [{"match": "*", "effort": 1000.0}]})
    model = PhysicsModel(robot, fit=("armature", "bodies"))
    params = [p for p in model.parameters() if p.requires_grad]
    assert not model.u_body_off.is_contiguous()  # the case torch's parameters_to_vector refuses
    theta = torch.cat([p.detach().reshape(-1) for p in params]).numpy()
    moved = theta + 0.01 * np.arange(len(theta)) / len(theta)
    values = _values(model, params, moved)
    back = torch.cat([p.detach().reshape(-1) for p in params]).numpy()
    np.testing.assert_allclose(back, moved, rtol=0, atol=1e-15)
    assert not np.allclose(values["body_mass"].numpy(), _values(model, params, theta)["body_mass"].numpy())
