"""The change detector and the effort grid of the online identifier (:mod:`wresdyn.adapt.detect`): a jump of the
held-back error above the recent median opens a tracking mode without confirmation; a joint whose drive saturates
below the model's effort limit gets a lower limit that wins on the held-back part."""

import numpy as np

from wresdyn.adapt.adapter import Adapter
from wresdyn.adapt.config import AdaptConfig
from wresdyn.adapt.detect import NORM_FLOOR, ChangeDetector, command_rate, demanded_torque, effort_candidates
from wresdyn.adapt.stream import dataset_blocks
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.sim.physics import PhysicalParams

SAT = Mismatch(kp_scale=0.8, kd_scale=1.3, friction=0.03, damping=0.3, torque_limit_scale=0.15)
"""A real robot whose drives saturate on the test motion (the right hip pitch asks for about 37 N·m, its limit is
0.15 x 88 = 13.2 N·m)."""
TINY = AdaptConfig(window=1.2, holdout=0.3, update_every=0.4, iterations=3, windows=4, horizon=16, one_step_every=10,
                   confirm=True, detect=True, detect_history=1.2, track_for=0.4, track_iterations=3)


def test_the_detector_fires_on_a_jump_above_the_recent_median_and_tracks_for_a_while():
    det = ChangeDetector(factor=2.0, history=4, track_for=3.0)
    noise = np.random.default_rng(0).uniform(0.8, 1.2, 10)  # the motion's second-to-second spread without drift
    for k, e in enumerate(noise):
        jumped, ratio, _ = det.observe(float(k), k - 1.0, 1e-3 * e, np.full(3, 1e-3 * e))
        assert not jumped and ratio < 2.0
        assert not det.tracking(float(k))
    jumped, ratio, joints = det.observe(10.0, 9.0, 3e-3, np.array([1e-3, 5e-3, 1e-3]))
    assert jumped and ratio > 2.5 and joints[1] > 4 and joints[0] < 1.5
    assert det.since == 9.0 and det.tracking(12.9) and not det.tracking(13.1)
    jumped, *_ = det.observe(11.0, 10.0, 3e-3, np.full(3, 3e-3))  # a second jump extends the mode, not its start
    assert det.since == 9.0 and det.tracking(13.9)


def test_normalised_by_the_command_a_swing_of_the_motion_is_not_a_jump_and_a_change_is():
    q_cmd = np.cumsum(np.full((11, 2), 0.01), 0)  # 0.01 rad per sample on both joints
    assert abs(command_rate(q_cmd) - 0.01) < 1e-12
    assert command_rate(q_cmd[:1]) == 0.0
    det = ChangeDetector(factor=2.0, history=4, track_for=3.0, norm=True)
    for k in range(4):
        det.observe(float(k), k - 1.0, 1e-3, np.full(3, 1e-3), scale=0.01)
    # the motion three times as fast, its error three times as large: no jump (the raw detector's would be 3)
    jumped, ratio, _ = det.observe(4.0, 3.0, 3e-3, np.full(3, 3e-3), scale=0.03)
    assert not jumped and abs(ratio - 1.0) < 1e-9
    # the same motion, the error three times as large: a change
    jumped, ratio, _ = det.observe(5.0, 4.0, 3e-3, np.full(3, 3e-3), scale=0.01)
    assert jumped and abs(ratio - 3.0) < 1e-9
    # a robot coming to rest: the command hardly moves, its motion counts as NORM_FLOOR times the recent median
    rest = ChangeDetector(factor=2.0, history=4, track_for=3.0, norm=True)
    for k in range(4):
        rest.observe(float(k), k - 1.0, 1e-3, np.full(3, 1e-3), scale=0.01)
    jumped, ratio, _ = rest.observe(4.0, 3.0, 0.2e-3, np.full(3, 0.2e-3), scale=1e-9)
    assert not jumped and abs(ratio - 0.2 / NORM_FLOOR) < 1e-9


def test_with_confirm_two_jumps_in_a_row_open_the_tracking_mode_from_the_first():
    det = ChangeDetector(factor=2.0, history=10, track_for=3.0, confirm=2)
    for k in range(4):  # the median stays 1e-3 rad below: at most three of the seven errors below are jumps
        det.observe(float(k), k - 1.0, 1e-3, np.full(3, 1e-3))
    jumped, ratio, _ = det.observe(4.0, 3.0, 3e-3, np.full(3, 3e-3))  # one swing of the motion: not yet
    assert not jumped and ratio > 2.0 and not det.tracking(4.0)
    assert not det.joint_ratios.any()  # nor for the effort grid
    det.observe(5.0, 4.0, 1e-3, np.full(3, 1e-3))  # back down: the streak ends
    assert det.observe(6.0, 5.0, 3e-3, np.full(3, 3e-3))[0] is False
    jumped, *_ = det.observe(7.0, 6.0, 3e-3, np.full(3, 3e-3))  # the second in a row: the data after the first
    assert jumped and det.tracking(7.0) and det.since == 5.0
    assert (det.joint_ratios > 2.0).all()


def test_a_joint_jump_counts_for_the_effort_grid_only_where_the_overall_error_rose_too():
    det = ChangeDetector(factor=2.0, history=4, track_for=3.0, overall=1.0)
    for k in range(4):
        det.observe(float(k), k - 1.0, 1e-3, np.full(3, 1e-3))
    # the motion moves to joint 1: its error jumps, the others' fall, and the overall error with them
    jumped, ratio, joints = det.observe(4.0, 3.0, 0.9e-3, np.array([0.2e-3, 2.5e-3, 0.1e-3]))
    assert not jumped and ratio < 1.0 and joints[1] > 2.0
    assert not det.joint_ratios.any()
    det.observe(5.0, 4.0, 1.5e-3, np.array([1e-3, 3.5e-3, 1e-3]))  # above its median overall: the joint counts
    assert det.joint_ratios[1] > 2.0 and det.joint_ratios[0] == det.joint_ratios[2] == 0.0
    plain = ChangeDetector(factor=2.0, history=4, track_for=3.0)  # overall 0: every joint jump counts
    for k in range(4):
        plain.observe(float(k), k - 1.0, 1e-3, np.full(3, 1e-3))
    plain.observe(4.0, 3.0, 0.9e-3, np.array([0.2e-3, 2.5e-3, 0.1e-3]))
    assert plain.joint_ratios[1] > 2.0


def test_the_effort_grid_tries_only_limits_below_the_demanded_torque():
    t = np.linspace(0, 1, 50)[:, None]
    q, qd, target = np.zeros((50, 2)), np.zeros((50, 2)), np.hstack([0.1 * t, 0.5 * t])
    demand = demanded_torque(np.array([100.0, 100.0]), np.array([1.0, 1.0]), q, qd, target)
    np.testing.assert_allclose(demand, [10.0, 50.0])
    physics = type("P", (), {"effort": np.array([40.0, 40.0])})()
    assert effort_candidates(physics, [0, 1], demand, (0.2, 0.5, 0.9)) == [(0, 8.0), (1, 8.0), (1, 20.0), (1, 36.0)]


def _stream(humanoid, record):
    return record(humanoid, SAT, {"train": 1}, seconds=1.6, amplitude=0.3)


def test_in_the_tracking_mode_a_winner_is_kept_without_confirmation(humanoid, record):
    stream = _stream(humanoid, record)
    cfg = TINY.__class__(**{**TINY.__dict__, "lr": 0.02, "effort_grid": (), "detect_jump_confirm": False,
                                "track_leave": True})

    def first_update(cfg, history=True):
        adapter = Adapter(humanoid, PhysicalParams.nominal(humanoid), stream.rate_hz, cfg)
        if history:  # a recent level far below any error: the first update jumps
            adapter.detector.errors.extend([1e-6] * 3)
            adapter.detector.joints.extend([np.full(humanoid.n_dof, 1e-6)] * 3)
        return adapter, adapter.push(*next(iter(dataset_blocks(stream))))[0]

    adapter, u = first_update(cfg)
    assert u.tracking and u.jump > 100
    assert u.accepted and not u.pending and u.open_loop == u.open_loop_candidate < u.open_loop_before
    # the tracking mode trains on the samples after the jump where they hold a window, else on all
    x, seg = np.random.default_rng(0).normal(size=(300, 3, humanoid.n_dof)), np.zeros(300, dtype=np.int64)
    after = adapter._train(x, seg, np.arange(300) >= 200)
    assert len(after) == 1 and np.array_equal(after[0].q, x[200:, 0])
    assert len(adapter._train(x, seg, np.arange(300) >= 295)[0].q) == 300  # 5 samples: no window, all of them
    _, v = first_update(cfg, history=False)  # no history: guarded mode
    assert not v.tracking and not v.accepted and v.pending
    # detect_jump_confirm: the update that detects the jump fitted its candidate before it, so confirms it; with
    # track_leave = False not even the tracking mode takes the model off the warm start unconfirmed; with
    # track_confirm the tracking mode's candidates wait for a confirmation as in the guarded mode
    for option in ({"detect_jump_confirm": True}, {"track_leave": False}, {"track_confirm": True}):
        _, w = first_update(cfg.__class__(**{**cfg.__dict__, **option}))
        assert w.tracking and w.jump > 100 and not w.accepted and w.pending, option


def test_a_saturating_joint_gets_its_lower_effort_limit_from_the_grid(humanoid, record):
    # the warm start is the real robot except the right hip pitch's limit, 1/0.3 times too high: its drive
    # saturates on the robot and never in the model; the grid's 0.3 is the truth. Only this joint's error is above
    # its recent level: the next update picks on the held-back part that showed it, keeps on its own
    stream = _stream(humanoid, record)
    truth = RealRobot(humanoid, SAT).physics()
    j = humanoid.joint_names.index("right_hip_pitch")
    start = truth.copy()
    start.effort[j] = truth.effort[j] / 0.3
    cfg = TINY.__class__(**{**TINY.__dict__, "lr": 1e-6, "effort_joints": 1})
    adapter = Adapter(humanoid, start, stream.rate_hz, cfg)
    det = adapter.detector
    det.errors.extend([1e-6] * 3)
    joints = np.full(humanoid.n_dof, 1.0)
    joints[j] = 1e-6
    det.joints.extend([joints] * 3)
    updates = [u for block in dataset_blocks(stream) for u in adapter.push(*block)]
    assert updates[0].effort_tried == 0  # no jump seen before it
    kept = [u for u in updates if u.effort_set]
    assert kept and kept[0].effort_set.startswith("right_hip_pitch="), [u.effort_set for u in updates]
    u = kept[0]
    assert u.effort_tried >= 1
    np.testing.assert_allclose(adapter.physics.effort[j], truth.effort[j], rtol=1e-6)
    assert np.array_equal(np.delete(adapter.physics.effort, j), np.delete(start.effort, j))
    assert u.accepted and u.open_loop < 0.95 * u.open_loop_before
    np.testing.assert_allclose(adapter.model.values().effort[j], truth.effort[j], rtol=1e-5)
