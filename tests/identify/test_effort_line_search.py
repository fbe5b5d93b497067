"""The per-joint effort line search (:func:`wresdyn.identify.unexcited_limits.search_unexcited_efforts`,
``SysIdConfig.effort_line_points``) on a small recording whose true parameters are known: a saturating drive whose
limit is put at its own largest demand (what the demanded-torque bound keeps when a fit explains the clipped torque
away) comes back down to the truth; the validation guard refuses a worse candidate; identification runs it last."""

import dataclasses

import numpy as np
import pytest

from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.identify.sysid import PhysicsScore, SysIdConfig, identify
from wresdyn.identify.unexcited_limits import demanded_torque, limit_unexcited_efforts, search_unexcited_efforts

SCALE = 0.2
"""Every real drive's limit as a fraction of the file's: the shared derating the search goes down to."""
CFG = SysIdConfig(fit=("effort",), iterations=4, windows=4, horizon_curriculum=(16,), select_every=2,
                  effort_grid=(0.5,), effort_after=0.0, effort_line_points=4)


@pytest.fixture(scope="module")
def case(humanoid, record):
    """(data, true parameters, the joint made unexcited, those parameters with its limit at its largest demand)."""
    mismatch = Mismatch(torque_limit_scale=SCALE)
    data = record(humanoid, mismatch, {"train": 2, "validation": 1}, seconds=0.3, amplitude=0.3)
    truth = RealRobot(humanoid, mismatch, data.rate_hz).physics()
    tau = demanded_torque(truth, data.split("train"), 1.0 / data.rate_hz)
    share = (tau > truth.effort).mean(0)
    # the joint that saturates least but still counts as identified: the ankle pitch's 1.3 % on the uneven mismatch
    k = int(np.flatnonzero(share >= CFG.saturated_min)[np.argmin(share[share >= CFG.saturated_min])])
    high = truth.copy()
    high.effort = np.where(np.arange(humanoid.n_dof) == k, 1.01 * tau[:, k].max(), truth.effort)
    return data, truth, k, high


def test_a_limit_held_at_its_demand_comes_down_to_the_truth(humanoid, case):
    data, truth, k, high = case
    train, dt = data.split("train"), 1.0 / data.rate_hz
    _, found = limit_unexcited_efforts(high, humanoid.effort, train, dt)
    assert humanoid.joint_names[k] in found.changed and found.ratio == pytest.approx(SCALE)
    assert high.effort[k] > 1.2 * truth.effort[k]  # the bound alone would keep it there
    lines = []
    score = PhysicsScore(humanoid, data.split("validation"), data.rate_hz)
    out, v = search_unexcited_efforts(CFG, humanoid, data, train, dt, high, score, score(high), lines.append)
    # the data were recorded at the truth, which is the line's lowest point: its replay error is the least there
    assert out.effort[k] == pytest.approx(truth.effort[k], rel=1e-9)
    others = np.arange(humanoid.n_dof) != k
    np.testing.assert_allclose(out.effort[others], high.effort[others], rtol=1e-9)
    assert any(x.startswith(f"effort line search {humanoid.joint_names[k]}:") for x in lines)
    assert v == score(out) and high.effort[k] > truth.effort[k]  # the input is not modified


def test_the_searched_limit_is_the_lowest_within_the_tolerance(humanoid, case):
    # a far lower derating: the pick is the line's lowest point whose own training error is within the tolerance of
    # the least, and never below the derating
    data, truth, k, high = case
    train, dt = data.split("train"), 1.0 / data.rate_hz
    low = high.copy()
    low.effort = np.where(np.arange(humanoid.n_dof) == k, high.effort[k], 0.5 * truth.effort)  # derating 0.1
    cfg = dataclasses.replace(CFG, effort_line_points=6, effort_line_tolerance=0.05)
    lines = []
    out, _ = search_unexcited_efforts(cfg, humanoid, data, train, dt, low, None, None, lines.append)
    (line,) = [x for x in lines if x.startswith(f"effort line search {humanoid.joint_names[k]}:")]
    points = [tuple(float(v) for v in p.split(":")) for p in line.split(": ", 1)[1].split("  ->")[0].split()]
    limits, errors = np.array(points).T
    assert limits[-1] == pytest.approx(0.5 * SCALE * humanoid.effort[k], rel=1e-2)  # down to the derating
    within = errors <= 1.05 * errors.min() * (1 + 1e-3)  # the log's rounding
    assert out.effort[k] == pytest.approx(limits[np.flatnonzero(within).max()], rel=1e-2)
    assert errors[-1] > 1.05 * errors.min() and within.sum() < len(within)  # half the true limit: too low


def test_a_worse_validation_keeps_the_selected_limits(humanoid, case):
    data, _, _, high = case
    lines = []
    out, v = search_unexcited_efforts(CFG, humanoid, data, data.split("train"), 1.0 / data.rate_hz, high,
                                      lambda p: 1.03, 1.0, lines.append)
    assert out is high and v == 1.0 and lines[-1].startswith("  not kept")
    out, v = search_unexcited_efforts(CFG, humanoid, data, data.split("train"), 1.0 / data.rate_hz, high,
                                      lambda p: 1.01, 1.0, lines.append)
    assert out is not high and v == 1.01  # within the 2 % tolerance


def test_identification_runs_the_search_last_and_only_lowers(humanoid, case):
    data = case[0]
    lines = []
    searched, _ = identify(humanoid, data, CFG, log=lines.append)
    plain, _ = identify(humanoid, data, dataclasses.replace(CFG, effort_line_points=0), log=lambda *_: None)
    assert np.all(searched.effort <= plain.effort)
    for name in ("kp", "kd", "friction", "damping", "armature", "delay"):
        np.testing.assert_array_equal(getattr(searched, name), getattr(plain, name))
    assert any(x.startswith("effort line search") for x in lines)


def test_the_search_needs_the_effort_limit_fitted():
    with pytest.raises(ValueError, match="effort_line_points"):
        SysIdConfig(fit=("kp", "friction"), effort_line_points=4)
