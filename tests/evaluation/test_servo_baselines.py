"""The MuJoCo C baselines of the SO-101 benchmark (:mod:`wresdyn.evaluation.servo_baselines`) on the shipped
5-run subset (data/so101/logs): the torque-drive path reproduces MuJoCo's own position actuator, so the BAM-style
drive, which uses that path, is applied the way MuJoCo applies forces; the BAM law itself is checked analytically."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from wresdyn.data.importers import SplitRule, import_runs, load_split_map
from wresdyn.data.logs import LogMap
from wresdyn.evaluation.servo_baselines import (
    BAM_STS3215_7V4,
    LEROBOT_KP,
    BamDrive,
    PDDrive,
    evaluate_baseline,
    lerobot_model,
    motors,
    replay,
)
from wresdyn.robot.description import load_robot

REPO = Path(__file__).resolve().parents[2]
SO101 = REPO / "scenes" / "so101" / "so101.xml"
RATE = 500.0
SAME_FORCE_RAD = 1e-9
"""Both paths evaluate kp·ctrl − kp·q − kv·q̇ from the same state in the same order; what remains is MuJoCo's own
arithmetic (e.g. fused multiply-adds) over 500 steps, far below an encoder tick (1.5e-3 rad)."""


@pytest.fixture(scope="module")
def subset():
    """The shipped subset imported with its map and split map, each run cut to its first second."""
    ds = import_runs([REPO / "data" / "so101" / "logs"], load_robot(SO101), RATE,
                     LogMap.load(REPO / "data" / "so101" / "map.toml"),
                     SplitRule("train", tuple(load_split_map(REPO / "data" / "so101" / "splits.toml"))))
    for tr in ds.trajectories:
        for k in ("t", "q", "qd", "qdd", "q_cmd"):
            setattr(tr, k, getattr(tr, k)[: int(RATE)])
    return ds


@pytest.mark.parametrize("kp, kv", [(LEROBOT_KP, 0.0), (998.22, 2.731)])
def test_torque_drive_reproduces_mujocos_position_actuator(subset, kp, kv):
    """LeRobot's gains and the robot file's: a position actuator and a motor fed τ = clip(kp·(q_cmd − q) − kv·q̇)
    computed before each step from the same state give the same replay; a drive applied one step late, or from the
    state after the step, would not."""
    trajs = subset.split("validation") + subset.split("ood")
    pos = lerobot_model(SO101, RATE)
    pos.actuator_gainprm[:, 0], pos.actuator_biasprm[:, 1], pos.actuator_biasprm[:, 2] = kp, -kp, -kv
    limit = pos.actuator_forcerange[:, 1].copy()
    torque = lerobot_model(SO101, RATE)
    motors(torque)
    a = replay(pos, trajs)
    b = replay(torque, trajs, lambda q0: PDDrive(np.full(6, kp), np.full(6, kv), limit))
    for qa, qb in zip(a.q, b.q):
        np.testing.assert_allclose(qa, qb, rtol=0, atol=SAME_FORCE_RAD)
        assert np.abs(qa - qa[0]).max() > 0.01  # the arm moved
    assert a.diverged_at == b.diverged_at == [-1] * len(trajs)


def test_lerobot_model_is_the_robot_file_with_lerobots_gains():
    import mujoco

    m, f = lerobot_model(SO101, RATE), mujoco.MjModel.from_xml_path(str(SO101))
    np.testing.assert_array_equal(m.actuator_gainprm[:, 0], LEROBOT_KP)
    np.testing.assert_array_equal(m.actuator_biasprm[:, :3], [[0, -LEROBOT_KP, 0]] * 6)
    np.testing.assert_array_equal(m.actuator_forcerange, [[-3.35, 3.35]] * 6)
    for field in ("dof_damping", "dof_frictionloss", "dof_armature", "body_mass", "jnt_range"):
        np.testing.assert_array_equal(getattr(m, field), getattr(f, field))
    np.testing.assert_array_equal(m.dof_damping, 0.6)
    assert m.opt.timestep == 1 / RATE


def test_bam_drive_law():
    """Firmware target moving at most max_velocity per second; saturated duty gives the DC motor's torque-speed
    line, zero torque at the no-load speed vin·max_pwm/kt."""
    p = BAM_STS3215_7V4
    drive = BamDrive(p, np.zeros(1))
    dt = 0.002
    no_load = p.vin * p.max_pwm / p.kt
    tau = drive(np.zeros(1), np.array([no_load]), np.array([10.0]), dt)
    assert drive.target[0] == pytest.approx(p.max_velocity * dt)
    assert tau[0] == pytest.approx(p.kt / p.R * p.vin * min(p.max_pwm, p.max_velocity * dt * p.kp * p.error_gain)
                                   - p.kt**2 / p.R * no_load)
    for _ in range(200):  # the target reaches the error that saturates the duty cycle
        tau = drive(np.zeros(1), np.array([no_load]), np.array([10.0]), dt)
    assert tau[0] == pytest.approx(0.0, abs=1e-12)
    stall = drive(np.zeros(1), np.zeros(1), np.array([10.0]), dt)[0]
    assert stall == pytest.approx(p.kt / p.R * p.vin * p.max_pwm)
    assert 3.2 < stall < 3.4  # the STS3215's 7.4 V stall torque as BAM identifies it, near the file's 3.35 N*m


def test_evaluate_baseline_scores_like_the_project(subset):
    """The improvement is PD-only mean |dq| / model mean |dq| over the fitted joints (gripper excluded)."""
    trajs = subset.split("heldout")
    pd_only = {"mean_abs_dq": 0.02}
    s = evaluate_baseline(lerobot_model(SO101, RATE), trajs, pd_only, weights=subset.fit_weights())
    assert s["model"]["n_joints"] == 5 and s["improvement"] == pytest.approx(0.02 / s["model"]["mean_abs_dq"])
    assert math.isfinite(s["model"]["mean_abs_dq"]) and s["model"]["diverged"] == 0
