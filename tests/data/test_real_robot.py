"""The simulated real robot: nominal parity with MuJoCo, each mismatch term, config parsing, the gap."""

from pathlib import Path

import numpy as np
import pytest

from wresdyn.data.mismatch import Mismatch, MismatchError
from wresdyn.data.real_robot import RealRobot, collect
from wresdyn.evaluation.open_loop import pd_gap

RATE = 500.0
DEFAULT_TOML = Path(__file__).resolve().parents[2] / "data" / "mismatch_default.toml"


def _command(robot, seconds=0.6, seed=0):
    """A smooth multisine about mid-range, well inside the limits, shape (T, n_dof)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * RATE))[:, None] / RATE
    lo, hi = robot.lower, robot.upper
    f = rng.uniform(0.5, 3.0, size=robot.n_dof)
    return 0.5 * (lo + hi) + 0.2 * (hi - lo) * np.sin(2 * np.pi * f * t) * np.clip(t / 0.2, 0, 1)


def test_nominal_is_exactly_mujoco_replay(humanoid):
    """All mismatch off and substep = recording step: the same model and the same steps as mujoco_replay."""
    from wresdyn.robot.mujoco_model import build_mujoco, mujoco_replay

    q_cmd = _command(humanoid)
    q, qd, tau = RealRobot(humanoid, Mismatch(), RATE).record(q_cmd, settle=0.0)
    q_ref, qd_ref = mujoco_replay(build_mujoco(humanoid, 1.0 / RATE), q_cmd, q_cmd[0])
    np.testing.assert_array_equal(q, q_ref[:-1])
    np.testing.assert_array_equal(qd, qd_ref[:-1])
    assert Mismatch().is_nominal() and not Mismatch.load(DEFAULT_TOML).is_nominal()


def test_mismatch_changes_the_model_fields(humanoid):
    nominal = RealRobot(humanoid, Mismatch(), RATE).model
    mm = Mismatch(friction=0.1, damping=0.5, armature_scale=2.0, mass_error=0.1, com_error=0.01, inertia_error=0.1,
                  kp_scale=0.8, kd_scale=1.5, torque_limit_scale=0.5, seed=3)
    m = RealRobot(humanoid, mm, RATE).model
    np.testing.assert_allclose(m.dof_frictionloss, 0.1 * humanoid.effort)
    np.testing.assert_allclose(m.dof_damping, 0.5 * humanoid.kd)
    np.testing.assert_allclose(m.dof_armature, 2.0 * nominal.dof_armature)
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], 0.8 * humanoid.kp)
    np.testing.assert_allclose(m.actuator_biasprm[:, 2], -1.5 * humanoid.kd)
    np.testing.assert_allclose(m.actuator_forcerange[:, 1], 0.5 * humanoid.effort)
    assert not np.allclose(m.body_mass, nominal.body_mass)
    assert np.abs(m.body_ipos - nominal.body_ipos).max() > 1e-3
    # one physical robot: the same seed draws the same link errors
    np.testing.assert_array_equal(RealRobot(humanoid, mm, RATE).model.body_mass, m.body_mass)


def test_delay_shifts_the_commands_exactly(humanoid):
    """A delay of m recording steps is the nominal robot fed m extra steps of the first command."""
    q_cmd = _command(humanoid, 0.3)
    m = 3
    delayed = RealRobot(humanoid, Mismatch(delay=m / RATE, substep=0.001), RATE).record(q_cmd)[0]
    padded = np.concatenate([np.repeat(q_cmd[:1], m, axis=0), q_cmd])
    nominal = RealRobot(humanoid, Mismatch(substep=0.001), RATE).record(padded)[0]
    np.testing.assert_array_equal(delayed, nominal[: len(q_cmd)])


def test_a_mismatch_changed_mid_recording_changes_only_what_follows(humanoid):
    """The ``on_sample`` hook: a hook that changes nothing leaves the recording as it was; friction doubled at sample
    k leaves samples 0..k as they were and changes what follows, and ``physics()`` then reads the new friction."""
    q_cmd = _command(humanoid, 0.3)
    real = RealRobot(humanoid, Mismatch(friction=0.05), RATE)
    q, qd, _ = real.record(q_cmd)
    seen = []
    np.testing.assert_array_equal(real.record(q_cmd, on_sample=lambda k, m: seen.append(k))[0], q)
    assert seen == list(range(len(q_cmd)))
    base = real.model.dof_frictionloss.copy()

    def double_at(k, m):
        if k == 75:
            m.dof_frictionloss[:] = 2.0 * base

    q2, qd2, _ = real.record(q_cmd, on_sample=double_at)
    np.testing.assert_array_equal(q2[:76], q[:76])
    assert np.abs(q2[76:] - q[76:]).max() > 1e-4
    np.testing.assert_allclose(real.physics().friction, 2.0 * base)


def test_torque_saturation_and_sensors(humanoid):
    q_cmd = _command(humanoid, 0.4)
    q_cmd[50:] += 0.3 * np.sign(0.5 * (humanoid.lower + humanoid.upper) - q_cmd[50:])  # a step: large torques
    clean = RealRobot(humanoid, Mismatch(torque_limit_scale=0.1), RATE)
    q0, qd0, tau = clean.record(q_cmd)
    assert (np.abs(tau) <= 0.1 * humanoid.effort * (1 + 1e-9)).all()
    assert (np.abs(tau) >= 0.1 * humanoid.effort * 0.999).any(), "the step should saturate some joint"
    res = 2.0 ** -12
    noisy = RealRobot(humanoid, Mismatch(torque_limit_scale=0.1, position_noise=1e-3, velocity_noise=0.05,
                                         encoder_resolution=res), RATE)
    q, qd, _ = noisy.record(q_cmd, np.random.default_rng(0))
    np.testing.assert_array_equal(q, np.round(q / res) * res)  # quantised
    # the physics is the same, only the measurement differs: noise of the configured size
    assert 0.8e-3 < (q - q0).std() < 1.2e-3
    assert 0.04 < (qd - qd0).std() < 0.06
    with pytest.raises(ValueError, match="Generator"):
        noisy.record(q_cmd)


def test_mismatch_config_file(tmp_path):
    mm = Mismatch.load(DEFAULT_TOML)
    assert mm.friction > 0 and mm.delay > 0 and mm.torque_limit_scale < 1 and mm.substep == 0.001
    assert Mismatch.from_dict(mm.to_dict()) == mm
    bad = tmp_path / "bad.toml"
    for text, match in [("fricton = 0.1\n", "unknown key"), ("friction = -1.0\n", ">= 0"),
                        ("friction = 'a lot'\n", "must be a number"), ("seed = 1.5\n", "integer"),
                        ("kp_scale = 0.0\n", "> 0"), ("friction = \n", "malformed TOML")]:
        bad.write_text(text)
        with pytest.raises(MismatchError, match=match) as e:
            Mismatch.load(bad)
        assert str(bad) in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(MismatchError, match="not found"):
        Mismatch.load(tmp_path / "missing.toml")


def test_substep_must_divide_the_step(humanoid):
    with pytest.raises(MismatchError, match="does not divide"):
        RealRobot(humanoid, Mismatch(substep=0.0015), RATE)


def test_default_mismatch_opens_a_gap_the_nominal_robot_does_not(humanoid):
    """PD-only Newton replay against the recorded robot: with the default mismatch the gap is many times the
    Newton-vs-MuJoCo integration difference of the nominal robot (a few 1e-3 rad)."""
    counts = {"heldout": 1}
    real = collect(humanoid, Mismatch.load(DEFAULT_TOML), counts, duration=1.0, seed=1).split("heldout")
    nominal = collect(humanoid, Mismatch(substep=0.001), counts, duration=1.0, seed=1).split("heldout")
    np.testing.assert_array_equal(real[0].q_cmd, nominal[0].q_cmd)  # same excitation, different robot
    gap = pd_gap(humanoid, real + [_renamed(nominal[0])], RATE)["per_trajectory"]
    assert gap["heldout_000"] > 0.03
    assert gap["nominal"] < 0.01
    assert gap["heldout_000"] > 5 * gap["nominal"]


def test_seeding_is_per_split_and_stable(humanoid):
    """Adding a validation split leaves every train / held-out / OOD array bit-identical (fixed spawn keys per
    split); validation is ellipsoid excitation (the training family) drawn from seeds of its own."""
    from wresdyn.data.real_robot import SPAWN_KEYS

    assert SPAWN_KEYS == {"train": 0, "heldout": 1, "ood": 2, "validation": 3}  # schema-1 keys kept
    mm = Mismatch.load(DEFAULT_TOML)
    without = collect(humanoid, mm, {"train": 1, "heldout": 1, "ood": 1}, duration=0.06, seed=2)
    with_val = collect(humanoid, mm, {"train": 1, "validation": 2, "heldout": 1, "ood": 1}, duration=0.06, seed=2)
    assert [tr.name for tr in with_val.trajectories] == ["train_000", "validation_000", "validation_001",
                                                         "heldout_000", "ood_000"]
    for tr in without.trajectories:
        again = next(x for x in with_val.trajectories if x.name == tr.name)
        for f in ("t", "q", "qd", "qdd", "q_cmd", "tau"):
            np.testing.assert_array_equal(getattr(tr, f), getattr(again, f), err_msg=f"{tr.name}.{f}")
    params = with_val.meta["trajectory_params"]
    assert params["validation_000"]["family"] == params["validation_001"]["family"] == "ellipsoid"
    cmds = [tr.q_cmd for tr in with_val.trajectories]  # every trajectory, validation too, has its own draw
    assert all(np.abs(a - b).max() > 1e-3 for i, a in enumerate(cmds) for b in cmds[i + 1:])
    with pytest.raises(ValueError, match="unknown split"):
        collect(humanoid, mm, {"test": 1}, duration=0.06)


def _renamed(tr):
    from dataclasses import replace

    return replace(tr, name="nominal")


def test_collect_command(tmp_path, capsys):
    from wresdyn.cli import main
    from wresdyn.data.dataset import load_dataset

    out = tmp_path / "out"
    args = ["collect", "--train", "1", "--validation", "1", "--heldout", "0", "--ood", "1", "--duration", "0.3",
            "--no-gap", "--out", str(out)]
    assert main(args) == 0
    printed = capsys.readouterr().out
    assert "[1/3] train_000" in printed and "[2/3] validation_000" in printed and "[3/3] ood_000" in printed
    ds = load_dataset(out / "dataset.npz")
    assert [tr.split for tr in ds.trajectories] == ["train", "validation", "ood"]
    assert ds.mismatch == Mismatch.load(DEFAULT_TOML).to_dict()
    assert (out / "spectrum.png").stat().st_size > 0
    bad = tmp_path / "bad.toml"
    bad.write_text("delay_ms = 5\n")
    assert main(["collect", "--mismatch", str(bad), "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("wresdyn collect: error:") and str(bad) in err and "\n" not in err
    assert not (tmp_path / "x").exists()  # nothing written on a config error


def test_per_joint_and_per_link_mismatch_by_name_pattern(humanoid, tmp_path):
    """[[joint]] and [[link]] entries override the global scalars on the names they match, later entries win; the
    shipped second mismatch loads; bad entries are one-line errors."""
    mm = Mismatch.from_dict({"friction": 0.1, "kp_scale": 0.8,
                             "joint": [{"match": "*_knee", "friction": 0.3}, {"match": "left_knee", "kp_scale": 0.5}],
                             "link": [{"match": "torso", "mass_scale": 1.5, "com_offset": [0.01, 0.0, 0.02]}]})
    t = RealRobot(humanoid, mm).physics()
    names = list(humanoid.joint_names)
    knee, rknee, hip = names.index("left_knee"), names.index("right_knee"), names.index("left_hip_pitch")
    np.testing.assert_allclose(t.friction[[knee, rknee, hip]], [0.3, 0.3, 0.1] * humanoid.effort[[knee, rknee, hip]])
    np.testing.assert_allclose(t.kp[[knee, rknee]], [0.5, 0.8] * humanoid.kp[[knee, rknee]])
    torso = list(humanoid.body_names).index("torso")
    assert t.body_mass[torso] == pytest.approx(1.5 * humanoid.body_mass[torso])
    np.testing.assert_allclose(t.body_com[torso], humanoid.body_com[torso] + [0.01, 0.0, 0.02], atol=1e-9)
    assert Mismatch.from_dict(mm.to_dict()) == mm
    assert not Mismatch.load(Path(__file__).parents[2] / "data" / "mismatch_uneven.toml").is_nominal()
    with pytest.raises(MismatchError, match="unknown key 'frction'"):
        Mismatch.from_dict({"joint": [{"match": "*", "frction": 0.1}]})
    with pytest.raises(MismatchError, match="com_offset"):
        Mismatch.from_dict({"link": [{"match": "torso", "com_offset": [0.1]}]})
    with pytest.raises(MismatchError, match="matches no joint"):
        RealRobot(humanoid, Mismatch.from_dict({"joint": [{"match": "tail_*", "friction": 0.1}]}))


def test_the_real_floor_differs_and_the_stand_does_not(humanoid, floating):
    """The shipped mismatches give the real robot a floor of their own friction and contact time constant (every
    geom: MuJoCo takes the larger friction and the mean solref of a pair); a mismatch without floor keys (an older
    file or dataset header) keeps the nominal floor; a robot on its stand has no floor, and its model does not change.
    A softer floor lets a 3 cm drop sink deeper (measured 5.7 mm nominal, 8.9 mm default, 12.0 mm uneven)."""
    import dataclasses
    from operator import attrgetter

    from wresdyn.robot.contact import ContactSettings
    from wresdyn.robot.ground import standing_state

    nominal = ContactSettings()
    uneven = Mismatch.load(DEFAULT_TOML.parent / "mismatch_uneven.toml")
    default = Mismatch.load(DEFAULT_TOML)
    for mm, friction, timeconst in ((default, 0.7, 0.03), (uneven, 0.6, 0.04)):
        assert friction < nominal.friction and timeconst > nominal.timeconst
        real = RealRobot(floating, mm, RATE)
        assert real.contact.friction == pytest.approx(friction) and real.contact.timeconst == pytest.approx(timeconst)
        np.testing.assert_allclose(real.model.geom_friction[:, 0], friction)
        np.testing.assert_allclose(real.model.geom_solref[:, 0], timeconst)
        np.testing.assert_allclose(real.model.geom_solref[:, 1], nominal.dampratio)
    old = {k: v for k, v in default.to_dict().items() if not k.startswith("floor_")}
    assert RealRobot(floating, Mismatch.from_dict(old), RATE).contact == nominal
    # the stand: the floor keys change nothing
    stand, stand_old = RealRobot(humanoid, default, RATE), RealRobot(humanoid, Mismatch.from_dict(old), RATE)
    assert stand.contact is None
    for f in ("geom_friction", "geom_solref", "body_mass", "dof_frictionloss", "actuator_gainprm", "opt.timestep"):
        np.testing.assert_array_equal(attrgetter(f)(stand.model), attrgetter(f)(stand_old.model))
    with pytest.raises(MismatchError, match="floor_timeconst_scale = 0.0 must be > 0"):
        Mismatch.from_dict({"floor_timeconst_scale": 0.0})
    # softer: a drop from 3 cm sinks deeper into it
    st = standing_state(floating)
    drop = dataclasses.replace(st, base_pose=st.base_pose + np.array([0, 0, 0.03, 0, 0, 0, 0]))
    deepest = []
    for scale in (1.0, 2.0):
        real = RealRobot(floating, Mismatch(floor_timeconst_scale=scale, substep=0.001), RATE)
        real.reset(drop)
        low = 0.0
        for _ in range(100):
            real.step(st.q)
            d = real._data
            low = min(low, float(d.contact.dist[:d.ncon].min(initial=0.0)))
        deepest.append(-low)
    assert 4e-3 < deepest[0] < 8e-3 and deepest[1] > 1.6 * deepest[0]
