"""Table I reward terms against hand-computed values."""

import math

import pytest
import torch

from wresdyn.ppo import rewards as R


def t(*rows):
    return torch.tensor(rows, dtype=torch.float32)


def test_kernel_is_exp_of_negative_squared_norm_over_sigma():
    # |x|^2 = 0.01 + 0.04 = 0.05 = sigma -> e^-1; zero error -> 1
    assert R.kernel(t([0.1, 0.2]), 0.05).item() == pytest.approx(math.exp(-1.0), rel=1e-6)
    assert R.kernel(t([0.0, 0.0]), 0.05).item() == 1.0


def test_mimic_terms_compare_with_the_recording():
    q, q_r = t([0.3, -0.1]), t([0.2, 0.1])  # diff (0.1, -0.2): |.|^2 = 0.05
    assert R.joint_pos_mimic(q, q_r, 0.1).item() == pytest.approx(math.exp(-0.5), rel=1e-6)
    qd, qd_r = t([1.0, 2.0]), t([0.0, 0.0])  # |.|^2 = 5
    assert R.joint_vel_mimic(qd, qd_r, 10.0).item() == pytest.approx(math.exp(-0.5), rel=1e-6)


def test_position_bonus_counts_joints_within_tolerance():
    q_r = t([0.0, 0.0, 0.0, 0.0])
    q = t([0.0005, 0.002, -0.0009, 0.5])  # joints 0 and 2 are within 1e-3
    assert R.joint_pos_bonus(q, q_r, 1e-3).item() == pytest.approx(0.5)
    assert R.joint_pos_bonus(q_r, q_r, 1e-3).item() == 1.0


def test_squared_norm_penalties():
    x = t([1.0, 2.0, -2.0])  # 1 + 4 + 4
    assert R.joint_torque(x).item() == pytest.approx(9.0)
    assert R.joint_vel(x).item() == pytest.approx(9.0)
    assert R.joint_acc(x).item() == pytest.approx(9.0)


def test_action_rate_and_acceleration():
    a, a1, a2 = t([1.0, 0.0]), t([0.5, 1.0]), t([0.5, 3.0])
    assert R.action_rate(a, a1).item() == pytest.approx(0.25 + 1.0)
    # a - 2 a1 + a2 = (1 - 1 + 0.5, 0 - 2 + 3) = (0.5, 1)
    assert R.action_acc(a, a1, a2).item() == pytest.approx(0.25 + 1.0)


def test_defaults_are_table_one_and_terms_are_weighted():
    cfg = R.RewardConfig()
    table = {"joint_pos_mimic": 5.0, "joint_vel_mimic": 3.0, "joint_pos_bonus": 10.0, "joint_torque": -0.5e-5,
             "joint_vel": -0.5e-3, "joint_acc": -0.5e-6, "action_rate": -0.5e-4, "action_acc": -0.5e-6}
    assert {k: getattr(cfg, k) for k in R.TERMS} == table
    z = torch.zeros(2, 3)
    one = torch.ones(2, 3)
    terms = R.reward_terms(cfg, q=z, qd=one, qdd=2 * one, q_r=z, qd_r=z, tau=3 * one, a=one, a_prev=z, a_prev2=z)
    assert list(terms) == list(R.TERMS)
    expect = {
        "joint_pos_mimic": 5.0,  # exact match
        "joint_vel_mimic": 3.0 * math.exp(-3.0 / cfg.sigma_qd),
        "joint_pos_bonus": 10.0,
        "joint_torque": -0.5e-5 * 27.0,
        "joint_vel": -0.5e-3 * 3.0,
        "joint_acc": -0.5e-6 * 12.0,
        "action_rate": -0.5e-4 * 3.0,
        "action_acc": -0.5e-6 * 3.0,
    }
    for k, v in expect.items():
        assert terms[k].shape == (2,)
        assert terms[k][0].item() == pytest.approx(v, rel=1e-5), k
