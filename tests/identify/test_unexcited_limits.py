"""Effort limits the data never reaches (:mod:`wresdyn.identify.unexcited_limits`): exact checks on small synthetic
recordings whose demanded torques are known in closed form, then the identification that uses it."""

from types import SimpleNamespace

import numpy as np
import pytest

from wresdyn.identify.sysid import SysIdConfig, identify
from wresdyn.identify.unexcited_limits import demanded_torque, limit_unexcited_efforts
from wresdyn.robot.physical import PhysicalParams

DT = 0.002
T = 1000


def _params(effort, kp=(100.0, 100.0, 100.0, 100.0), delay=0.0):
    n = len(effort)
    return PhysicalParams([f"j{i}" for i in range(n)], ["b"], np.array(kp[:n], float), np.zeros(n), np.zeros(n),
                          np.zeros(n), np.zeros(n), np.array(effort, float), np.full(n, delay), np.ones(1),
                          np.zeros((1, 3)), np.eye(3)[None])


def _recording(amplitude):
    """q = 0, q̇ = 0 and commands a sine of ``amplitude`` [rad] per joint: the demanded torque is kp·q_cmd."""
    t = np.arange(T) * DT
    q_cmd = np.stack([a * np.sin(2 * np.pi * t) for a in amplitude], axis=1)
    return SimpleNamespace(q=np.zeros_like(q_cmd), qd=np.zeros_like(q_cmd), q_cmd=q_cmd)


def test_demanded_torque_sees_the_commands_through_each_joints_delay():
    rec = _recording([0.1, 0.2])
    tau = demanded_torque(_params([1.0, 1.0], delay=3 * DT), [rec], DT)
    shifted = np.concatenate([np.repeat(rec.q_cmd[:1], 3, axis=0), rec.q_cmd[:-3]])
    np.testing.assert_allclose(tau, 100.0 * np.abs(shifted), rtol=1e-12, atol=1e-12)


def test_unexcited_joints_take_the_saturating_joints_ratio():
    # joints 0 and 2 demand up to 30 N·m against limits of 20 and 10 (ratios 0.2, 0.25 of the file): identified;
    # joint 1 demands at most 2 N·m against 40 (0.4 of its file's 100): it takes the median ratio 0.225
    file = np.array([100.0, 100.0, 40.0])
    params = _params([20.0, 40.0, 10.0])
    out, found = limit_unexcited_efforts(params, file, [_recording([0.3, 0.02, 0.3])], DT)
    assert found.ratio == pytest.approx(0.225)
    assert found.changed == ("j1",)
    np.testing.assert_allclose(out.effort, [20.0, 22.5, 10.0])
    assert params.effort[1] == 40.0  # the input is not modified
    assert found.saturated[1] == 0.0 and found.saturated[0] > 0.5


def test_the_data_bounds_an_unexcited_limit_from_below():
    # joint 1 demands up to 30 N·m: below its 40 N·m limit (never saturated), above the shared ratio's 22.5
    file = np.array([100.0, 100.0, 40.0])
    params = _params([20.0, 40.0, 10.0])
    out, found = limit_unexcited_efforts(params, file, [_recording([0.3, 0.3, 0.3])], DT)
    assert found.changed == ("j1",)
    tau = demanded_torque(params, [_recording([0.3, 0.3, 0.3])], DT)
    assert 22.5 < out.effort[1] <= 30.0
    assert out.effort[1] == found.bound[1] == tau[:, 1].max()  # the training data demands no more than it has


def test_nothing_changes_where_nothing_saturates_or_a_joint_is_not_fitted():
    file = np.array([100.0, 100.0, 40.0])
    quiet = [_recording([0.01, 0.01, 0.01])]
    out, found = limit_unexcited_efforts(_params([20.0, 40.0, 10.0]), file, quiet, DT)
    assert found.ratio is None and found.changed == ()
    np.testing.assert_array_equal(out.effort, [20.0, 40.0, 10.0])
    out, found = limit_unexcited_efforts(_params([20.0, 40.0, np.inf]), file, [_recording([0.3, 0.02, 0.02])], DT,
                                         fitted=[True, False, True])
    assert found.changed == ()  # j1 is excluded from fitting, j2's drive is unlimited
    np.testing.assert_array_equal(out.effort, [20.0, 40.0, np.inf])


def test_identification_shares_the_ratio_and_never_selects_worse(humanoid, record):
    # on a robot whose drives are all derated to a fifth of the file, small commands saturate some drives and not
    # others: identification gives the others the saturating ones' ratio, exactly as the function does on the
    # parameters it would otherwise return (the two runs are the same up to that last step)
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.identify.sysid import PhysicsScore

    data = record(humanoid, Mismatch(torque_limit_scale=0.2), {"train": 2, "validation": 1}, seconds=0.3,
                  amplitude=0.3)
    cfg = SysIdConfig(fit=("effort",), iterations=4, windows=4, horizon_curriculum=(16,), select_every=2,
                      effort_grid=(0.5,), effort_after=0.0)
    lines = []
    shared, _ = identify(humanoid, data, cfg, log=lines.append)
    kept, _ = identify(humanoid, data, SysIdConfig(**{**cfg.__dict__, "share_effort_ratio": False}),
                       log=lambda *_: None)
    expected, found = limit_unexcited_efforts(kept, humanoid.effort, data.split("train"), 1.0 / data.rate_hz)
    assert found.ratio is not None and 0 < len(found.changed) < humanoid.n_dof, found.describe()
    assert found.describe() in lines
    score = PhysicsScore(humanoid, data.split("validation"), data.rate_hz)
    if any(x.startswith("  not kept") for x in lines):
        np.testing.assert_array_equal(shared.effort, kept.effort)
    else:
        np.testing.assert_array_equal(shared.effort, expected.effort)
        assert score(shared) <= score(kept)
