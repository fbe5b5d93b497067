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
    # MuJoCo's writer keeps about 6 significant digits of the principal moments and axes
    np.testing.assert_allclose(inertia[heavy], p.body_inertia[heavy], atol=1e-5 * np.abs(p.body_inertia).max())
    report = json.loads((out / "mjcf_report.json").read_text())
    # the one note: the soft friction's impedance per joint (test_the_soft_friction_is_wresdyns_at_any_armature)
    assert [n[:9] for n in report["notes"]] == ["friction:"] and report["friction_kappa"] is None
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


def _physics_only_run(tmp_path, data, physics, config=None):
    """A physics-only run folder (as `wresdyn identify` leaves one) on ``data`` with ``physics``."""
    data.save(tmp_path / "dataset.npz")
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"data_path": str(tmp_path / "dataset.npz"), **(config or {})}))
    physics.save(run / "physics.json")
    return run


def test_the_so101_servo_model_round_trips_through_mujoco_actuators(tmp_path, record):
    """The SO-101 (MJCF, STS3215 servo drives) recorded on its bench real robot (scenes/so101/mismatch.toml), the
    servo model's physics (with encoder offsets of up to 30 mrad, the actuators' bias) exported by default as MJCF:
    position actuators with the back-EMF in the joint damping and the goal profile in servo.json. Held-out error of
    MuJoCo within 10 % of the wresdyn model's (measured 0.0459 against 0.0456 rad with play_mujoco's servo law, 0.0461
    with the position actuators alone); without the goal profile
    it is far larger (measured 0.0677 rad), so the report's loss is real."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.paths import REPO
    from wresdyn.robot.description import load_robot
    from wresdyn.sim.physics import PhysicalParams

    so101 = REPO / "scenes" / "so101"
    robot = load_robot(so101 / "so101.xml", gains=so101 / "servo.toml")
    data = record(robot, Mismatch.load(so101 / "mismatch.toml"), {"heldout": 2}, 0.6, amplitude=0.3)
    data.gains = robot.gains_record()
    physics = PhysicalParams.nominal(robot)
    physics.encoder_offset = np.array([0.02, -0.03, 0.01, 0.0, -0.02, 0.03])  # the actuators' bias carries it
    run = _physics_only_run(tmp_path, data, physics)
    assert main(["export", str(run), "--physics-only"]) == 0  # an MJCF robot: mjcf by default
    out = run / "export"
    report = json.loads((out / "mjcf_report.json").read_text())
    trip, bare = report["round_trip"], report["round_trip_without_goal_profile"]
    plain = report["round_trip_position_actuators"]
    print(trip, plain, bare)
    # play_mujoco's servo law follows wresdyn closer than the position actuators do (measured 4.1e-4 against 5.6e-4)
    assert trip["between"] < 0.85 * plain["between"], (trip, plain)
    assert set(json.loads((out / "servo.json").read_text())["law"]) >= {"deadband", "backlash", "stiction", "mask",
                                                                         "load_friction"}
    assert abs(trip["mujoco"] - trip["wresdyn"]) <= 0.1 * trip["wresdyn"], trip
    assert bare["mujoco"] > 1.3 * trip["mujoco"], (bare, trip)
    servo_notes = [n for n in report["notes"] if not n.startswith("friction:")]
    assert len(servo_notes) == robot.n_dof and all("deadband" in n for n in servo_notes)
    accel = json.loads((out / "servo.json").read_text())["goal_accel"]
    np.testing.assert_allclose(accel, robot.servo.goal_accel)
    assert not (out / "residual.onnx").exists()


def test_servo_encoder_offset_and_backlash_in_the_mjcf(tmp_path):
    """The encoder offset o as the position actuator's bias ``-kp o`` (its force ``kp (ctrl - q - o)``, checked on
    the compiled model), the backlash named in the report's notes as dropped (MuJoCo has no gear play)."""
    import mujoco

    from wresdyn.export.mjcf import _mapping, mjcf_spec
    from wresdyn.paths import REPO
    from wresdyn.robot.description import load_robot
    from wresdyn.sim.physics import PhysicalParams

    so101 = REPO / "scenes" / "so101"
    robot = load_robot(so101 / "so101.xml", gains=so101 / "servo.toml")
    physics = PhysicalParams.nominal(robot)
    physics.encoder_offset = np.linspace(-0.03, 0.03, robot.n_dof)
    physics.backlash = np.full(robot.n_dof, 0.009)
    spec, notes = mjcf_spec(robot, physics, 50.0)
    model = spec.compile()
    d = mujoco.MjData(model)
    d.qpos[:] = 0.1
    d.ctrl[:] = 0.3
    mujoco.mj_forward(model, d)
    want = np.clip(physics.kp * (0.3 - 0.1 - physics.encoder_offset), -physics.effort, physics.effort)
    np.testing.assert_allclose(d.actuator_force, want, rtol=1e-9, atol=1e-12)
    servo_notes = [n for n in notes if not n.startswith("friction:")]
    assert len(servo_notes) == robot.n_dof and all("backlash 0.009" in n for n in servo_notes)
    assert "backlash" in _mapping() and "encoder_offset" in _mapping()


def test_a_damper_law_run_exports_with_frictionloss_and_says_so(tmp_path, humanoid, data):
    """A run identified under the damper friction law: its friction amplitudes become MuJoCo's frictionloss and
    the report names the change (the USD export maps it to Newton's joint friction the same way)."""
    import mujoco

    p = _physics(humanoid)
    run = _physics_only_run(tmp_path, data, p, {"friction_kappa": 947.0})
    assert main(["export", str(run), "--physics-only", "--format", "mjcf", "--out", str(tmp_path / "out")]) == 0
    report = json.loads((tmp_path / "out" / "mjcf_report.json").read_text())
    assert report["friction_kappa"] == 947.0 and any("damper law" in n for n in report["notes"])
    m = mujoco.MjModel.from_xml_path(str(tmp_path / "out" / "robot.xml"))
    dofs = m.jnt_dofadr[m.actuator_trnid[:, 0]]
    np.testing.assert_allclose(m.dof_frictionloss[dofs], p.friction, rtol=1e-6)
    # the damper's rate as the friction constraint's impedance, no pull to the old velocity; MuJoCo scales the
    # impedance's rate by m0 / H_ii (m0 = 1 / dof_invweight0), taken out at the reference pose
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    full = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, full)
    c = 947.0 * m.opt.timestep * np.diag(full)[dofs] * m.dof_invweight0[dofs]
    assert (c > 947.0 * m.opt.timestep * 1.01).any()  # coupled joints: the scale is not 1
    np.testing.assert_allclose(m.dof_solimp[dofs, :2], np.repeat((c / (1.0 + c))[:, None], 2, 1), rtol=1e-5)
    np.testing.assert_allclose(m.dof_solref[dofs, 0], 2.0 * m.opt.timestep * (1.0 + c) / c, rtol=1e-5)
    print(report["round_trip"])
    assert report["round_trip"]["between"] < 0.1 * report["round_trip"]["wresdyn"]


def test_the_soft_friction_is_wresdyns_at_any_armature(tmp_path, humanoid, data):
    """wresdyn's soft friction scales its regulariser by each DoF's reference inertia of the robot as built (the
    replay solver's ``fric_m0``), MuJoCo by ``1 / dof_invweight0`` of the exported model: with ten times the
    armature and 3 N m of friction on every joint the two differ up to tenfold, and the export's per-joint
    ``solimpfriction`` makes them one constraint again. Measured: the replays 8.5e-6 rad apart, MuJoCo's error 0.2 %
    from wresdyn's; with MuJoCo's default solimpfriction 1.35e-3 rad apart and -10 %."""
    import mujoco

    from wresdyn.export.mjcf import round_trip
    from wresdyn.export.mjcf_friction import MJ_SOLIMP_FRICTION
    from wresdyn.sim.physics import PhysicalParams
    from wresdyn.sim.simulator import Simulator

    p = PhysicalParams.nominal(humanoid)
    p.armature = p.armature * 10.0
    p.friction = np.full(humanoid.n_dof, 3.0)
    run = _physics_only_run(tmp_path, data, p)
    assert main(["export", str(run), "--physics-only", "--format", "mjcf", "--out", str(tmp_path / "out")]) == 0
    xml = tmp_path / "out" / "robot.xml"
    report = json.loads((tmp_path / "out" / "mjcf_report.json").read_text())
    trip = report["round_trip"]
    print(trip)
    assert trip["between"] < 3e-5 and abs(trip["mujoco"] - trip["wresdyn"]) <= 0.01 * trip["wresdyn"], trip
    assert any(n.startswith("friction:") and "solimpfriction" in n for n in report["notes"])
    # the impedance is the one the replay solver's own reference inertia asks for
    m = mujoco.MjModel.from_xml_path(str(xml))
    dofs = m.jnt_dofadr[m.actuator_trnid[:, 0]]
    m0 = Simulator(humanoid, 1, 1.0 / data.rate_hz).solver._reference_inertia().numpy()
    d = m.dof_solimp[dofs, 0]
    np.testing.assert_allclose(d / (1.0 - d), 9.0 * m0 * m.dof_invweight0[dofs], rtol=1e-4)
    np.testing.assert_allclose(m.dof_solimp[dofs, 1:], np.tile(MJ_SOLIMP_FRICTION[1:], (len(dofs), 1)))
    # MuJoCo's default impedance, the scale of the exported model: far apart
    spec = mujoco.MjSpec.from_file(str(xml))
    for j in spec.joints:
        j.solimp_friction = list(MJ_SOLIMP_FRICTION)
    (tmp_path / "default.xml").write_text(spec.to_xml())
    held = data.split("heldout")
    ref = round_trip(xml, humanoid, p, held, data.rate_hz)["q"]
    plain = round_trip(tmp_path / "default.xml", humanoid, p, held, data.rate_hz, reference=ref)
    plain.pop("q")
    print(plain)
    assert plain["between"] > 30 * trip["between"] and abs(plain["mujoco"] - plain["wresdyn"]) > 0.05 * trip["wresdyn"]


def test_a_urdf_robot_exports_to_mjcf(tmp_path, cartpole, record):
    """A URDF robot (Newton's cartpole): the MJCF loads and carries the identified gains."""
    import mujoco

    from wresdyn.data.mismatch import Mismatch
    from wresdyn.sim.physics import PhysicalParams

    data = record(cartpole, Mismatch(), {"train": 1, "heldout": 1}, 0.2)
    data.gains = cartpole.gains_record()
    p = PhysicalParams.nominal(cartpole)
    p.kp *= 1.2
    run = _physics_only_run(tmp_path, data, p)
    assert main(["export", str(run), "--physics-only"]) == 0
    m = mujoco.MjModel.from_xml_path(str(run / "export" / "robot.xml"))
    np.testing.assert_allclose(m.actuator_gainprm[:, 0], p.kp, rtol=1e-6)
    trip = json.loads((run / "export" / "mjcf_report.json").read_text())["round_trip"]
    assert abs(trip["mujoco"] - trip["wresdyn"]) <= 0.1 * trip["wresdyn"] + 1e-4, trip


def test_bad_runs_are_refused_in_one_line_and_nothing_is_written(tmp_path, humanoid, data, capsys):
    """No residual without --physics-only, an existing folder without --force: one line, non-zero, nothing new."""
    run = _physics_only_run(tmp_path, data, _physics(humanoid))
    assert main(["export", str(run), "--format", "mjcf"]) != 0
    err = capsys.readouterr().err.strip()
    assert "no residual" in err and len(err.splitlines()) == 1, err
    assert not (run / "export").exists()
    (run / "export").mkdir()
    assert main(["export", str(run), "--format", "mjcf", "--physics-only"]) != 0
    assert "already exists" in capsys.readouterr().err and not any((run / "export").iterdir())
    assert [p.name for p in run.iterdir() if p.name.startswith(".")] == []


def test_an_identified_inertia_off_the_triangle_inequality_is_moved_onto_it_and_named(humanoid):
    """MuJoCo refuses principal moments where one exceeds the sum of the others; the fit bounds them one by one, so an
    identified body can leave the set: the export lowers the largest to the bound, names it, and the model compiles."""
    from wresdyn.export.mjcf import mjcf_spec
    from wresdyn.robot.mujoco_model import mujoco_body_names
    from wresdyn.sim.physics import PhysicalParams

    physics = PhysicalParams.nominal(humanoid)
    b = int(np.argmax(physics.body_mass))
    physics.body_inertia[b] = np.diag([1e-3, 2e-3, 5e-3])  # 5e-3 > 1e-3 + 2e-3
    spec, notes = mjcf_spec(humanoid, physics, 500.0)
    model = spec.compile()
    hit = [n for n in notes if "triangle inequality" in n]
    assert len(hit) == 1 and "lowered to 0.0029999" in hit[0]
    moments = np.sort(model.body_inertia[model.body(mujoco_body_names(humanoid.body_names)[b]).id])
    assert moments[2] <= moments[0] + moments[1] + 1e-12
    assert np.allclose(moments, [1e-3, 2e-3, 3e-3], rtol=2e-5)


def test_play_mujoco_servo_law_is_wresdyns_servo_law():
    """play_mujoco.py carries its own copy of the servo law (it runs without wresdyn): the same torques as
    :func:`wresdyn.robot.servo.servo_torque` and :func:`~wresdyn.robot.servo.friction_bound` on random states, with
    every term on (dead band, startup torque, backlash, encoder offset, back-EMF, stiction, load friction)."""
    from wresdyn.export.play_mujoco import ServoLaw
    from wresdyn.robot.servo import STARTUP_RAMP, STICTION_SPEED, friction_bound, servo_torque

    rng = np.random.default_rng(0)
    n = 6
    p = {"kp": rng.uniform(5, 30, n), "kd": rng.uniform(0, 1, n), "effort": rng.uniform(1, 3, n),
         "deadband": rng.uniform(0, 0.01, n), "noload_speed": rng.uniform(3, 8, n),
         "startup_torque": rng.uniform(0, 0.2, n), "backlash": rng.uniform(0, 0.01, n),
         "encoder_offset": rng.uniform(-0.02, 0.02, n), "friction": rng.uniform(0, 0.1, n),
         "stiction": rng.uniform(0, 0.1, n), "damping": rng.uniform(0, 0.5, n), "load_friction": rng.uniform(0, 0.3, n)}
    law = ServoLaw({**{k: v.tolist() for k, v in p.items()}, "mask": [1.0] * n, "ramp": STARTUP_RAMP,
                    "stiction_speed": STICTION_SPEED}, None)
    for _ in range(200):
        goal, q, qd = rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-0.2, 0.2, n) * rng.integers(0, 2)
        q = np.where(rng.random(n) < 0.5, goal - rng.uniform(-0.02, 0.02, n), q)  # near the goal: band, play, ramp
        want = servo_torque(goal, q, qd, p["kp"], p["kd"], p["deadband"], p["effort"], p["noload_speed"],
                            startup_torque=p["startup_torque"], backlash=p["backlash"],
                            encoder_offset=p["encoder_offset"])
        np.testing.assert_allclose(law.torque(goal, q, qd), want, rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(law.friction(qd, want), friction_bound(qd, p["friction"], p["stiction"],
                                                                         p["load_friction"], want), rtol=1e-12)
        assert (law.friction(qd, want) > friction_bound(qd, p["friction"], p["stiction"])).any()
