"""The kick diagnosis's pieces (``benchmarks/skills/floor_kick_gap.py``): the delay line it replays commands through
and the real robot with one group of parameters transplanted from a calibrated robot."""

import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "benchmarks" / "skills"))

from floor_kick_gap import delayed, transplanted  # noqa: E402


def test_delayed_shifts_each_joint_by_its_own_delay():
    cmd = np.stack([np.arange(6.0), 10 + np.arange(6.0)], -1)
    out = delayed(cmd, np.array([2.0, 0.5]))
    # whole samples: the command two samples earlier, the first one before the start
    np.testing.assert_allclose(out[:, 0], [0, 0, 0, 1, 2, 3])
    # half a sample: halfway between this command and the one before (SimPlant's linear delay line)
    np.testing.assert_allclose(out[:, 1], [10, 10.5, 11.5, 12.5, 13.5, 14.5])


@pytest.fixture(scope="module")
def robots():
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    floating = load_robot(DEFAULT_ROBOT, base="floating")
    res = {"mismatch": Mismatch.load(ROOT / "data" / "mismatch_uneven.toml").to_dict()}
    nominal = RealRobot(floating, Mismatch(), 500.0)
    return res, floating, nominal.physics(), transplanted(res, floating, 500.0, nominal.physics(), "")


def test_transplant_one_effort_limit(robots):
    res, floating, ident, real = robots
    j = list(floating.joint_names).index("left_elbow")
    got = transplanted(res, floating, 500.0, ident, "effort:left_elbow").model.actuator_forcerange[:floating.n_dof]
    want = real.model.actuator_forcerange[:floating.n_dof].copy()
    assert got[j, 1] == pytest.approx(ident.effort[j]) and got[j, 1] > 3 * want[j, 1]  # the bad drive: 0.15 x
    want[j] = got[j]
    np.testing.assert_array_equal(got, want)


def test_transplant_the_floor_and_one_link(robots):
    res, floating, ident, real = robots
    assert real.contact.friction == pytest.approx(0.6)
    assert transplanted(res, floating, 500.0, ident, "floor").contact.friction == pytest.approx(1.0)
    b = list(floating.body_names).index("torso")
    m = transplanted(res, floating, 500.0, ident, "link:torso").model
    assert m.body_mass[b + 1] == pytest.approx(ident.body_mass[b])
    np.testing.assert_allclose(m.body_ipos[b + 1], ident.body_com[b])
    np.testing.assert_array_equal(np.delete(m.body_mass, b + 1), np.delete(real.model.body_mass, b + 1))
