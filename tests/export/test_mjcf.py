"""``wresdyn export RUN --format mjcf``: the calibrated robot as MJCF, loaded by plain MuJoCo in a fresh process,
replays held-out data as the wresdyn model it came from does.

The run folders are made as in ``test_export.py`` (a tiny recording on the shipped real robot, identified physics
moved by hand so every field differs from the robot file, a residual with weights large enough to matter).
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from wresdyn.cli import main

from test_export import _physics, _run


@pytest.fixture(scope="module")
def mjcf_export(tmp_path_factory, humanoid, data):
    tmp = tmp_path_factory.mktemp("mjcf")
    run = _run(tmp, humanoid, data)
    assert main(["export", str(run), "--out", str(tmp / "mjcf"), "--format", "mjcf"]) == 0
    return run, tmp / "mjcf"


def test_the_mjcf_carries_the_identified_physics(mjcf_export, humanoid):
    """Every identified field lands in the compiled model MuJoCo reads back from robot.xml."""
    import mujoco

    run, out = mjcf_export
    p = _physics(humanoid)
    m = mujoco.MjModel.from_xml_path(str(out / "robot.xml"))
    assert m.nu == humanoid.n_dof and m.opt.timestep == pytest.approx(0.002)
    dof = m.jnt_dofadr[m.actuator_trnid[:, 0]]
    np.testing.assert_allclose(m.dof_armature[dof], p.armature, rtol=1e-6)
    np.testing.assert_allclose(m.dof_damping[dof], p.damping, rtol=1e-6)
    np.testing.assert_allclose(m.dof_frictionloss[dof], p.friction, rtol=1e-6)
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], p.kp, rtol=1e-6)
    np.testing.assert_allclose(-m.actuator_biasprm[:, 2], p.kd, rtol=1e-6)
    finite = np.isfinite(p.effort)
    np.testing.assert_allclose(m.actuator_forcerange[finite, 1], p.effort[finite], rtol=1e-6)
    np.testing.assert_allclose(m.actuator_delay, p.delay, atol=1e-12)
    np.testing.assert_allclose(m.body_mass[1:], p.body_mass, rtol=1e-6)
    np.testing.assert_allclose(m.body_ipos[1:], p.body_com, atol=1e-9)
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_quat(m.body_iquat[1:], scalar_first=True).as_matrix()
    inertia = rot @ (m.body_inertia[1:, :, None] * np.eye(3)) @ rot.transpose(0, 2, 1)
    heavy = p.body_mass > 0
    np.testing.assert_allclose(inertia[heavy], p.body_inertia[heavy], atol=1e-6 * np.abs(p.body_inertia).max())
    report = json.loads((out / "mjcf_report.json").read_text())
    assert report["notes"] == [] and report["friction_kappa"] is None
    assert {"residual.onnx", "residual.json", "play_mujoco.py", "physics.json", "export.json"} <= {
        f.name for f in out.iterdir()}


def test_the_mjcf_round_trip_is_within_ten_percent_of_the_wresdyn_model(mjcf_export, humanoid, data):
    """Held-out: plain MuJoCo on robot.xml with residual.onnx (play_mujoco.py's loop) against the recording, and the
    wresdyn model (identified physics + residual in SolverReplay) against it: errors within 10 %; the residual's own
    effect on MuJoCo's replay is larger than the two replays' difference, so dropping it would fail."""
    import mujoco

    from wresdyn.export import play_mujoco

    run, out = mjcf_export
    trip = json.loads((out / "mjcf_report.json").read_text())["round_trip"]
    print(trip)
    assert abs(trip["mujoco"] - trip["wresdyn"]) <= 0.1 * trip["wresdyn"], trip
    traj = data.split("heldout")[0]
    m = mujoco.MjModel.from_xml_path(str(out / "robot.xml"))
    bare = play_mujoco.replay(m, traj.q_cmd, traj.q[0], traj.qd[0])[0]
    res = play_mujoco.Residual(str(out / "residual.onnx"), 1.0 / data.rate_hz)
    full = play_mujoco.replay(m, traj.q_cmd, traj.q[0], traj.qd[0], res, traj.qdd[0])[0]
    effect = np.abs(full - bare).mean()
    print(f"residual effect in MuJoCo {effect:.2e} rad")
    assert effect > 3 * trip["between"]


def test_play_mujoco_runs_in_a_fresh_process(mjcf_export, data, tmp_path):
    """The shipped script on the export folder alone: a fresh Python loads robot.xml and residual.onnx."""
    _, out = mjcf_export
    traj = data.split("heldout")[0]
    np.save(tmp_path / "cmd.npy", traj.q_cmd)
    r = subprocess.run([sys.executable, str(out / "play_mujoco.py"), str(out / "robot.xml"), str(tmp_path / "cmd.npy"),
                        "--residual", str(out / "residual.onnx"), "--out", str(tmp_path / "q.npy")],
                       capture_output=True, text=True, cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stderr
    q = np.load(tmp_path / "q.npy")
    assert q.shape == traj.q_cmd.shape and np.isfinite(q).all()
