"""Saturation probe: steps inside the limits, deterministic per seed, saturating the drives it sizes for."""

import numpy as np
import pytest

from wresdyn.data.mismatch import Mismatch
from wresdyn.data.probe import PROBE_FAMILY, SaturationProbe, saturation_probe
from wresdyn.data.real_robot import RealRobot, collect
from wresdyn.robot.description import RobotError

RATE = 500.0
DURATION = 1.5
"""Six chain positions x one step pair of 0.23 s: the shortest probe that holds every leg joint's step."""
CFG = SaturationProbe(steps=1)
STRONG = SaturationProbe(steps=1, effort_fraction=(1.5, 2.0))
"""Steps sized to 1.5-2x the file's limit: what saturates the nominal robot's drives."""


@pytest.fixture(scope="module")
def ik(humanoid):
    from wresdyn.data.ik import FootIK

    return FootIK(humanoid)


def _draw(humanoid, ik, seed, cfg=CFG):
    return saturation_probe(humanoid, ik.chains, humanoid.q0, DURATION, RATE, np.random.default_rng(seed), cfg)


def test_probe_stays_in_limits_holds_the_rest_and_is_deterministic(humanoid, ik):
    e = _draw(humanoid, ik, 0)
    assert e.family == PROBE_FAMILY and e.q_cmd.shape == (int(DURATION * RATE), humanoid.n_dof)
    lo, hi = humanoid.lower + CFG.limit_margin, humanoid.upper - CFG.limit_margin
    assert (e.q_cmd >= lo - 1e-12).all() and (e.q_cmd <= hi + 1e-12).all()
    legs = np.zeros(humanoid.n_dof, dtype=bool)
    legs[ik.dofs] = True
    assert np.ptp(e.q_cmd[:, ~legs], axis=0).max() == 0.0  # the upper body holds its home pose
    assert (np.ptp(e.q_cmd[:, legs], axis=0) > 0.1).all()  # every leg joint is stepped
    assert set(e.params["joints"]) == {humanoid.joint_names[j] for j in ik.dofs}
    # one joint of each chain at a time: at any instant at most one joint per leg is off its home
    off = np.abs(e.q_cmd - e.q_cmd[0]) > 1e-9
    for chain in ik.chains:
        assert off[:, chain].sum(axis=1).max() == 1
    np.testing.assert_array_equal(e.q_cmd, _draw(humanoid, ik, 0).q_cmd)
    assert np.abs(e.q_cmd - _draw(humanoid, ik, 1).q_cmd).max() > 0.05


def test_probe_demands_more_than_the_effort_limit_on_the_nominal_robot(humanoid, ik):
    """Steps sized above the file's limit: on the nominal robot (the file's limits) the PD demand
    kp·(q_cmd − q) − kd·q̇ on the recorded states exceeds the limit, and the drive delivers the limit, on every joint
    whose range allows the drawn step (``reach`` >= 1.5, the least ``effort_fraction`` draws: knees and hip pitch;
    the hip yaw, hip roll and ankle ranges are too short). The knee moves during the 10 ms rise, so its demand stays below kp·δ: 1.27-1.68 x the limit over
    seeds 0-2, hip pitch 1.42-2.92."""
    e = _draw(humanoid, ik, 0, STRONG)
    q, qd, tau = RealRobot(humanoid, Mismatch(), RATE).record(e.q_cmd)
    demand = np.abs(humanoid.kp * (e.q_cmd - q) - humanoid.kd * qd)
    reached = [n for n, p in e.params["joints"].items() if p["reach"] >= STRONG.effort_fraction[0]]
    assert {"left_knee", "right_knee", "left_hip_pitch", "right_hip_pitch"} <= set(reached)
    for name in reached:
        j = humanoid.joint_names.index(name)
        assert demand[:, j].max() > humanoid.effort[j], name
        assert np.abs(tau[:, j]).max() > 0.99 * humanoid.effort[j], name


def test_default_probe_saturates_the_derated_drives_of_the_uneven_robot(humanoid, ik):
    """The default steps (0.6-0.9 of the file's limit) drive every leg joint but ankle roll into the limit of the
    second benchmark mismatch's drives (0.2-0.3 of the file's); ankle roll's ±0.26 rad range is too short to ask
    kp·δ of its 15 N·m."""
    from wresdyn.paths import REPO

    real = RealRobot(humanoid, Mismatch.load(REPO / "data" / "mismatch_uneven.toml"), RATE)
    _, _, tau = real.record(_draw(humanoid, ik, 0).q_cmd, np.random.default_rng(0))
    at_limit = np.abs(tau).max(axis=0) >= 0.99 * real.model.actuator_forcerange[:humanoid.n_dof, 1]
    for j in ik.dofs:
        name = humanoid.joint_names[j]
        assert at_limit[j] == ("ankle_roll" not in name), name


def test_collect_adds_probes_to_train_and_leaves_the_rest_unchanged(humanoid, cartpole):
    counts = {"train": 1, "validation": 0, "heldout": 0, "ood": 1}
    plain = collect(humanoid, Mismatch(), counts, duration=DURATION)
    probed = collect(humanoid, Mismatch(), counts, duration=DURATION, probe=1, probe_config=CFG)
    assert [(tr.name, tr.split) for tr in probed.trajectories] == [
        ("train_000", "train"), ("train_probe_000", "train"), ("ood_000", "ood")]
    for a, b in zip(plain.trajectories, [probed.trajectories[0], probed.trajectories[2]]):
        np.testing.assert_array_equal(a.q_cmd, b.q_cmd)
        np.testing.assert_array_equal(a.q, b.q)
    assert "saturation_probe" not in plain.meta
    assert probed.meta["saturation_probe"]["trajectories"] == 1
    assert probed.meta["trajectory_params"]["train_probe_000"]["family"] == PROBE_FAMILY
    with pytest.raises(RobotError, match="foot excitation"):
        collect(cartpole, Mismatch(), {"train": 1}, duration=0.2, probe=1)


def test_probe_rejects_a_trajectory_too_short(humanoid, ik):
    with pytest.raises(RobotError, match="longer"):
        saturation_probe(humanoid, ik.chains, humanoid.q0, 0.2, RATE, np.random.default_rng(0))


DEFAULT_SHA256 = {0: "b4a9adbc52bb672c77eb8bda37e8d0ab37e6bb97fb92596af07b5660f9405802",
                  1: "99c62fec85f837fb4fa6b020977a97dc87f88d5b66b747684cf4acf69a3f2f27"}
"""sha256 of the default probe's q_cmd (4 s at 500 Hz, the humanoid's home pose), seeds 0 and 1, as drawn before the
``across`` option existed: the datasets recorded with the default probe stay reproducible."""


@pytest.mark.parametrize("seed", [0, 1])
def test_default_probe_draws_the_trajectories_it_drew_before_across(humanoid, ik, seed):
    import hashlib

    for cfg in (SaturationProbe(), SaturationProbe(across=False)):
        e = saturation_probe(humanoid, ik.chains, humanoid.q0, 4.0, RATE, np.random.default_rng(seed), cfg)
        assert hashlib.sha256(np.ascontiguousarray(e.q_cmd).tobytes()).hexdigest() == DEFAULT_SHA256[seed]
        assert not any("across" in s for p in e.params["joints"].values() for s in p["steps"])


def test_across_steps_the_short_ranged_joints_over_their_range_and_stays_in_limits(humanoid, ik):
    """Ankle roll (±0.26 rad, kp 40, file limit 50 N·m) has no side with room for its 0.6-0.9 x 50 N·m demand: with
    ``across`` each of its steps spans the range less the margins, 0.42 rad (kp·Δ = 0.34 of the file's limit, twice
    the 0.17 one side allows); the knees, which have room, step as without it."""
    across = SaturationProbe(steps=1, across=True)
    e, plain = _draw(humanoid, ik, 0, across), _draw(humanoid, ik, 0)
    lo, hi = humanoid.lower + CFG.limit_margin, humanoid.upper - CFG.limit_margin
    assert (e.q_cmd >= lo - 1e-12).all() and (e.q_cmd <= hi + 1e-12).all()
    for name in ("left_ankle_roll", "right_ankle_roll"):
        j = humanoid.joint_names.index(name)
        (step,) = e.params["joints"][name]["steps"]
        assert step["across"] and abs(step["delta"]) == pytest.approx(hi[j] - lo[j])
        assert np.ptp(e.q_cmd[:, j]) == pytest.approx(hi[j] - lo[j])
        assert e.params["joints"][name]["reach"] == pytest.approx(2 * plain.params["joints"][name]["reach"])
    for name in ("left_knee", "right_knee"):
        j = humanoid.joint_names.index(name)
        np.testing.assert_array_equal(e.q_cmd[:, j], plain.q_cmd[:, j])


def test_across_saturates_the_uneven_robots_ankle_pitch_longer(humanoid, ik):
    """On the second benchmark mismatch (drives at 0.3 of the file's 50 N·m on the ankles), from the neutral pose,
    ``across`` steps ankle pitch over its 1.30 rad (kp·Δ 52 N·m) where one side allowed 0.82 rad: both ankle pitches
    stay at their limit on more samples (from the foot workspace's home, where `collect` probes, they have room). Ankle
    roll does not reach its limit either way: the mismatch's friction (0.12 of the file's limit, 6 N·m) stalls it 0.16
    rad short of every command (module docstring)."""
    from wresdyn.paths import REPO

    real = RealRobot(humanoid, Mismatch.load(REPO / "data" / "mismatch_uneven.toml"), RATE)
    limit = real.model.actuator_forcerange[:humanoid.n_dof, 1]
    share = {}
    for cfg in (SaturationProbe(), SaturationProbe(across=True)):
        e = saturation_probe(humanoid, ik.chains, humanoid.q0, 4.0, RATE, np.random.default_rng(0), cfg)
        _, _, tau = real.record(e.q_cmd, np.random.default_rng(0))
        share[cfg.across] = (np.abs(tau) >= 0.99 * limit).mean(0)
    for name in ("left_ankle_pitch", "right_ankle_pitch"):
        j = humanoid.joint_names.index(name)
        assert share[True][j] > 1.5 * share[False][j] > 0, name


def test_collect_records_across_only_when_it_is_on(humanoid):
    counts = {"train": 0, "validation": 0, "heldout": 0, "ood": 0}
    plain = collect(humanoid, Mismatch(), counts, duration=DURATION, probe=1, probe_config=CFG)
    across = collect(humanoid, Mismatch(), counts, duration=DURATION, probe=1,
                     probe_config=SaturationProbe(steps=1, across=True))
    assert "across" not in plain.meta["saturation_probe"]  # a default dataset's meta names no option it did not use
    assert across.meta["saturation_probe"]["across"] is True
