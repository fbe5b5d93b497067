"""The SO-101 arm (scenes/so101/): its servo model as loaded, joint-space excitation within limits, speed and
effort, IK frames by name (position-only for a 5-joint chain, one-line refusals), and collect end to end."""

from __future__ import annotations

import numpy as np
import pytest

from wresdyn.cli import main
from wresdyn.data import excitation as ex
from wresdyn.data.dataset import read_header
from wresdyn.data.ik import FootIK
from wresdyn.data.loading import load_data
from wresdyn.paths import REPO
from wresdyn.robot.description import RobotError, load_robot

SO101 = REPO / "scenes" / "so101" / "so101.xml"
GAINS = REPO / "examples" / "gains" / "so101.toml"
JOINTS = ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper"]
RATE = 500.0


@pytest.fixture(scope="module")
def so101():
    return load_robot(SO101)


def test_so101_loads_with_its_servo_model(so101):
    r = so101
    assert r.joint_names == JOINTS and r.base == "fixed" and r.n_bodies == 7
    assert set(r.frames) == {"baseframe", "gripperframe"}
    np.testing.assert_allclose(r.body_mass.sum(), 0.632, atol=1e-3)
    # the file's position actuators (kp, kv) and force range (which Newton's importer leaves out)
    np.testing.assert_allclose(r.kp, 998.22)
    np.testing.assert_allclose(r.kd, 2.731)
    np.testing.assert_allclose(r.effort, 3.35)
    np.testing.assert_allclose(r.armature, 0.028)
    np.testing.assert_allclose(r.friction, 0.052)
    np.testing.assert_allclose(r.damping, 0.6)
    # new_calib: 0 rad inside every range (the middle of the calibrated range)
    assert np.all(r.lower < 0.0) and np.all(r.upper > 0.0)
    r.check_replay()
    assert r.gains is None and r.gains_record() is None
    # the example gains config states the same servo model
    g = load_robot(SO101, gains=GAINS)
    for f in ("kp", "kd", "effort", "armature", "friction", "damping", "lower", "upper"):
        np.testing.assert_allclose(getattr(g, f), getattr(r, f), err_msg=f)
    assert g.gains_record()["file"] == str(GAINS) and g.effort_given.all()


def test_so101_mismatch_loads_and_scales():
    from wresdyn.data.mismatch import Mismatch

    mm = Mismatch.load(REPO / "scenes" / "so101" / "mismatch.toml")
    assert mm.torque_limit_scale * 3.35 == pytest.approx(1.91, abs=0.01)  # 7.4 V STS3215 stall torque


@pytest.mark.parametrize("family", ex.JOINT_FAMILIES)
def test_joint_space_excitation_within_limits_speed_and_effort(so101, family):
    cfg = ex.ExcitationConfig(mode="joint")
    plan = ex.plan(so101, cfg)
    assert plan.mode == "joint" and plan.families("ood") == ex.JOINT_OOD_FAMILIES
    e = plan.generate(family, 2.0, RATE, np.random.default_rng(3))
    q = e.q_cmd
    assert q.shape == (1000, 6) and e.family == family
    assert (q >= so101.lower + 0.5 * cfg.limit_margin).all() and (q <= so101.upper - 0.5 * cfg.limit_margin).all()
    assert np.abs(np.diff(q, axis=0)).max() * RATE <= cfg.joint_max_velocity
    # the torque to follow it on the nominal robot (independent inverse dynamics) stays under the fraction
    import pinocchio as pin

    from wresdyn.robot.pinocchio_model import build_pinocchio

    model = build_pinocchio(so101)
    data = model.createData()
    qd = np.gradient(q, 1 / RATE, axis=0)
    qdd = np.gradient(qd, 1 / RATE, axis=0)
    tau = np.array([pin.rnea(model, data, q[k], qd[k], qdd[k]) for k in range(len(q))])
    tau += so101.damping * qd + so101.friction * np.sign(qd)
    assert np.abs(tau).max() <= cfg.effort_fraction * 3.35 + 1e-9
    assert e.params["peak_effort_fraction"] <= cfg.effort_fraction
    assert q.std(axis=0).min() > 0.01, q.std(axis=0)  # every joint moves
    assert np.abs(q[1] - q[0]).max() * RATE < 0.5  # starts (nearly) at rest


def test_auto_mode_and_foot_mode_on_named_frames(so101, humanoid):
    assert ex.plan(so101).mode == "joint"  # no sole sites
    # the arm's gripper frame is moved by 5 joints: it cannot follow a full pose, so its IK is position-only
    ik = FootIK(so101, ("gripperframe",))
    assert ik.position_only and list(ik.dofs) == [0, 1, 2, 3, 4]
    q_goal = np.array([0.3, -0.4, 0.5, 0.2, 0.1, 0.0])
    target, _ = ik.forward(q_goal)
    q, err = ik.solve(target, None, so101.q0)
    assert err[0, 0] < 1e-4 and q[5] == so101.q0[5]
    # the humanoid's 6-joint legs keep the full 6-D pose
    assert not FootIK(humanoid).position_only


def test_bad_ik_frames_are_refused_in_one_line(so101, capsys):
    cases = {("left_foot", "gripperframe"): "no site or body named left_foot",
             ("gripper", "moving_jaw_so101_v1"): "share joint(s)",
             ("lower_arm",): "along only 2 direction",
             ("shoulder",): "moved by 1 joint"}
    for frames, text in cases.items():
        with pytest.raises(RobotError, match=text.replace("(", r"\(").replace(")", r"\)")) as e:
            FootIK(so101, frames)
        assert "\n" not in str(e.value)
    assert main(["collect", "--robot", str(SO101), "--excitation.frames", "left_foot", "right_foot", "--out",
                 "/nonexistent/x"]) == 2
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1 and err[0].startswith("wresdyn collect: error:") and "left_foot, right_foot" in err[0]
    assert main(["collect", "--robot", str(SO101), "--excitation.frames", "gripperframe", "--excitation.mode",
                 "joint"]) == 2
    assert "no use with --excitation.mode joint" in capsys.readouterr().err


def test_collect_so101_end_to_end(tmp_path, capsys):
    out = tmp_path / "so101data"
    assert main(["collect", "--robot", str(SO101), "--gains", str(GAINS), "--train", "2", "--validation", "1",
                 "--heldout", "1", "--ood", "2", "--duration", "0.4", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "joint-space excitation of 6 joints" in text and "[6/6]" in text and "PD-only vs real on ood" in text
    header = read_header(out / "dataset.npz")
    assert header["robot_file"] == "scenes/so101/so101.xml" and header["gains"]["file"] == str(GAINS)
    assert header["meta"]["excitation"]["mode"] == "joint" and "workspace" not in header["meta"]
    params = header["meta"]["trajectory_params"]
    assert [params[f"ood_{i:03d}"]["family"] for i in range(2)] == ["chirp", "steps"]
    assert params["train_000"]["family"] == "multisine"
    ds, robot = load_data(str(out / "dataset.npz"))
    assert ds.joint_names == JOINTS and robot.gains_record()["config"] == header["gains"]["config"]
    for tr in ds.trajectories:
        assert np.isfinite(tr.q).all() and (tr.q_cmd >= robot.lower).all() and (tr.q_cmd <= robot.upper).all()
        assert np.abs(tr.q - tr.q_cmd).mean() < 0.3  # the real arm follows its commands
    assert (out / "spectrum.png").is_file()


def test_fit_and_eval_replay_on_the_stored_gains(tmp_path, monkeypatch):
    """`fit` and `eval` load the robot with the gains config stored in the dataset; `--gains` replaces it."""
    from wresdyn.data import loading

    gains = tmp_path / "quad.toml"
    gains.write_text('[[joint]]\nmatch = "*"\nkp = 60.0\nkd = 2.5\n[[joint]]\nmatch = "*_KFE"\nkp = 90.0\n')
    data = tmp_path / "q" / "dataset.npz"
    assert main(["collect", "--robot", "newton:quadruped.urdf", "--gains", str(gains), "--train", "1",
                 "--validation", "1", "--heldout", "1", "--ood", "0", "--duration", "0.1", "--no-gap",
                 "--out", str(data.parent)]) == 0
    kps = []  # the robot's kp of each load_data call the CLI makes
    original = loading.load_data

    def spy(*args, **kwargs):
        ds, robot = original(*args, **kwargs)
        kps.append(dict(zip(robot.joint_names, robot.kp.tolist())))
        return ds, robot

    monkeypatch.setattr(loading, "load_data", spy)
    names = load_robot("newton:quadruped.urdf", gains=gains).joint_names
    stored = {n: 90.0 if n.endswith("_KFE") else 60.0 for n in names}
    override = {n: 100.0 if n.endswith("_KFE") else 80.0 for n in stored}  # examples/gains/quadruped.toml
    run = tmp_path / "fit"
    tiny = ["--model", "network", "--iterations", "2", "--windows", "2", "--curriculum", "2"]
    assert main(["fit", str(data), *tiny, "--out", str(run)]) == 0
    assert main(["eval", str(run), "--splits", "heldout", "--joints", "1"]) == 0
    with pytest.warns(UserWarning, match="instead of the one stored"):
        assert main(["fit", str(data), *tiny, "--gains", str(REPO / "examples" / "gains" / "quadruped.toml"),
                     "--out", str(tmp_path / "fit2")]) == 0
    assert kps == [stored, stored, override]
