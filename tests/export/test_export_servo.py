"""``wresdyn export`` of a robot with servo drives: the servo law as Newton actuators, read back by plain Newton.

A three-joint USD arm (written here), two joints servos from a gains config (dead band, no-load speed, goal
acceleration; the third a PD drive), recorded on ``RealRobot``; the run's identified physics move every field,
the servo ones included. The plain-Newton side runs in its own process, as a user's script would: the export's
``servo_actuator.py`` registers its USD schema before the first stage is opened, which this test process (whose
USD schema registry is already built) cannot do.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from wresdyn.cli import main
from wresdyn.paths import REPO

from test_export import _run

EXAMPLE = REPO / "examples" / "calibrated_robot_newton.py"
_ENV = {**os.environ, "OMP_NUM_THREADS": "1"}

_LINK = """
    def Xform "{name}" (
        prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsMassAPI"{root}]
    )
    {{
        point3f physics:centerOfMass = (0, 0, -0.07)
        float3 physics:diagonalInertia = (0.0012, 0.0012, 0.0002)
        float physics:mass = {mass}
        quatf physics:principalAxes = (1, 0, 0, 0)
        double3 xformOp:translate = (0, 0, {z})
        uniform token[] xformOpOrder = ["xformOp:translate"]
    }}
"""
_JOINT = """
        def PhysicsRevoluteJoint "{name}" (
            prepend apiSchemas = ["PhysicsDriveAPI:angular", "NewtonJointAPI"]
        )
        {{
            float drive:angular:physics:damping = 0.01
            float drive:angular:physics:stiffness = 0.1
            uniform token drive:angular:physics:type = "force"
            uniform token physics:axis = "{axis}"
            rel physics:body0 = </arm/{parent}>
            rel physics:body1 = </arm/{child}>
            point3f physics:localPos0 = (0, 0, {offset})
            point3f physics:localPos1 = (0, 0, 0)
            quatf physics:localRot0 = (1, 0, 0, 0)
            quatf physics:localRot1 = (1, 0, 0, 0)
            float physics:lowerLimit = -90
            float physics:upperLimit = 90
        }}
"""


def arm_usda() -> str:
    """A hanging three-link arm (base, then pitch, pitch, roll joints 0.15 m apart), fixed to the world by its base."""
    links = "".join(_LINK.format(name=n, mass=m, z=z, root=', "PhysicsArticulationRootAPI"' if n == "base" else "")
                    for n, m, z in (("base", 1.0, 0.6), ("upper", 0.4, 0.6), ("lower", 0.3, 0.45), ("hand", 0.2, 0.3)))
    joints = "".join(_JOINT.format(name=n, axis=a, parent=p, child=c, offset=o) for n, a, p, c, o in (
        ("shoulder", "Y", "base", "upper", 0.0), ("elbow", "Y", "upper", "lower", -0.15),
        ("wrist", "X", "lower", "hand", -0.15)))
    return ('#usda 1.0\n(\n    defaultPrim = "arm"\n    metersPerUnit = 1\n    kilogramsPerUnit = 1\n'
            '    upAxis = "Z"\n)\n\n'
            'def PhysicsScene "physicsScene"\n{\n    vector3f physics:gravityDirection = (0, 0, -1)\n'
            '    float physics:gravityMagnitude = 9.81\n}\n\ndef Xform "arm"\n{' + links
            + '\n    def "joints"\n    {' + joints + "    }\n}\n")


GAINS = {"joint": [
    {"match": "*", "kp": 12.0, "kd": 0.1, "effort": 2.5, "armature": 0.01, "damping": 0.05, "friction": 0.02},
    {"match": "[se]*", "drive": "servo", "deadband": 0.02, "noload_speed": 6.0, "goal_accel": 30.0},
]}
"""Servos on the shoulder and elbow (wrist PD): a dead band the 0.3 rad commands leave and re-enter, a torque–speed
line (U / w0 = 0.42 N m s/rad, four times kd) and a goal profile that lags the 3 Hz components of the command."""


def _servo_physics(robot):
    from wresdyn.sim.physics import PhysicalParams

    p = PhysicalParams.nominal(robot)
    p.kp *= 1.1
    p.kd *= 0.9
    p.armature *= 1.3
    p.damping += 0.02
    p.friction += 0.01
    p.effort = 0.9 * p.effort
    p.delay = np.array([0.004, 0.0, 0.004])  # 2 steps at 500 Hz
    p.deadband = p.deadband * 1.2
    p.noload_speed = p.noload_speed * 0.9
    p.goal_accel = p.goal_accel * 1.1
    p.backlash = np.array([0.01, 0.015, 0.0])  # the servos' gear play [rad]
    p.encoder_offset = np.array([0.01, -0.02, 0.0])  # signed [rad]
    p.startup_torque = np.array([0.15, 0.1, 0.0])  # [N m], the drive's minimum past the dead band
    p.body_mass = p.body_mass * 1.05
    return p


@pytest.fixture(scope="module")
def servo_export(tmp_path_factory, record):
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.robot.description import load_robot

    tmp = tmp_path_factory.mktemp("servo_export")
    (tmp / "arm.usda").write_text(arm_usda())
    robot = load_robot(tmp / "arm.usda", gains=GAINS)
    assert robot.servo.mask.tolist() == [True, True, False]
    data = record(robot, Mismatch(), {"train": 1, "heldout": 1}, 0.6, amplitude=0.3)
    data.gains = robot.gains_record()
    run = _run(tmp, robot, data, physics=False, scale=10.0)
    _servo_physics(robot).save(run / "physics.json")
    assert main(["export", str(run), "--out", str(tmp / "calibrated")]) == 0
    return robot, data, run, tmp / "calibrated", tmp / "dataset.npz"


def test_servo_export_writes_the_component_schema_and_parameters(servo_export):
    from pxr import Sdf, Usd

    from wresdyn.export import servo_actuator, usd
    from wresdyn.sim.physics import PhysicalParams

    robot, _, run, out, _ = servo_export
    assert usd.SERVO_SCHEMA == servo_actuator.SCHEMA
    assert (out / "servo_actuator.py").read_bytes() == Path(servo_actuator.__file__).read_bytes()
    schema = Sdf.Layer.FindOrOpen(str(out / servo_actuator.SCHEMA_DIR / "generatedSchema.usda"))
    assert set(schema.GetPrimAtPath(f"/{servo_actuator.SCHEMA}").properties.keys()) == set(servo_actuator._ATTRS)
    meta = json.loads((out / "export.json").read_text())["servo"]
    assert meta["joints"] == ["shoulder", "elbow"] and meta["schema"] == "WresdynServoControlAPI"
    want = PhysicalParams.load(run / "physics.json", robot)
    act = Usd.Stage.Open(str(out / "actuated.usda"))
    for i, name in enumerate(robot.joint_names):
        prim = act.GetPrimAtPath(f"/arm/wresdyn_actuators/{name}")
        schemas = list(prim.GetMetadata("apiSchemas").GetAddedOrExplicitItems())
        joint = act.GetPrimAtPath(f"/arm/joints/{name}")
        if i == 2:  # the PD wrist keeps its PD drive
            assert schemas[0] == "NewtonPDControlAPI" and not joint.GetAttribute("wresdyn:servo:deadband")
            continue
        assert schemas[0] == "WresdynServoControlAPI" and "NewtonDCMotorClampingAPI" in schemas
        assert ("NewtonActuatorDelayAPI" in schemas) == (i == 0)  # 4 ms on the shoulder, none on the elbow
        get = lambda a: prim.GetAttribute(a).Get()  # noqa: E731
        assert get("newton:servoDeadband") == pytest.approx(want.deadband[i], rel=1e-6)
        assert get("newton:servoGoalAccel") == pytest.approx(want.goal_accel[i], rel=1e-6)
        assert get("newton:servoBackEmf") == pytest.approx(want.effort[i] / want.noload_speed[i], rel=1e-6)
        assert get("newton:servoBacklash") == pytest.approx(want.backlash[i], rel=1e-6) and want.backlash[i] > 0
        assert get("newton:servoEncoderOffset") == pytest.approx(want.encoder_offset[i], rel=1e-6)
        assert get("newton:servoStartupTorque") == pytest.approx(want.startup_torque[i], rel=1e-6)
        assert want.startup_torque[i] > 0
        assert want.encoder_offset[i] != 0
        assert joint.GetAttribute("wresdyn:servo:encoderOffset").Get() == pytest.approx(want.encoder_offset[i])
        assert get("newton:velocityLimit") == pytest.approx(want.noload_speed[i], rel=1e-6)
        assert get("newton:saturationEffort") == get("newton:maxMotorEffort") == pytest.approx(want.effort[i], rel=1e-6)
        assert joint.GetAttribute("wresdyn:servo:deadband").Get() == pytest.approx(want.deadband[i])


def test_registering_after_usd_built_its_schema_registry_is_refused(servo_export):
    """This process has opened USD stages (the fixture's export), so USD's schema registry is built without the
    servo schema: Newton's importer would not see the servo drive (its parser stops at "no drive schema"), and
    :func:`register` says why first."""
    from wresdyn.export import servo_actuator

    with pytest.raises(RuntimeError, match="before opening any USD stage"):
        servo_actuator.register()


_LAW = """
import sys, numpy as np, warp as wp
sys.path.insert(0, sys.argv[1])
import servo_actuator
servo_actuator.register()
from newton.actuators import Actuator, ClampingDCMotor, ClampingMaxEffort
from wresdyn.robot.servo import play, profile_step, servo_torque
wp.config.quiet = True
rng = np.random.default_rng(0)
n, dt = 64, 0.002
f = lambda x: wp.array(np.asarray(x, dtype=np.float32))
kp, kd, b, a, U, w0 = (rng.uniform(lo, hi, n) for lo, hi in ((5, 30), (0, .5), (0, .05), (0, 60), (1, 3), (3, 10)))
w0[::4] = 0.0
a[::3] = 0.0
bl, off = np.where(np.arange(n) % 2 == 1, rng.uniform(0, .05, n), 0), rng.uniform(-.05, .05, n)
u0 = np.where(np.arange(n) % 5 < 3, np.random.default_rng(1).uniform(0, 0.5, n), 0)  # rng's draws stay as they were
worst, ramped = 0.0, 0
for dc in (True, False):
    sel = w0 > 0 if dc else w0 == 0
    idx = np.flatnonzero(sel)
    m = len(idx)
    drive = servo_actuator.DriveServo(f(kp[idx]), f(kd[idx]), f(b[idx]), f(a[idx]),
                                      f(np.where(w0[idx] > 0, U[idx] / np.where(w0[idx] > 0, w0[idx], 1), 0)),
                                      f(bl[idx]), f(off[idx]), f(u0[idx]))
    clamp = ClampingDCMotor(f(U[idx]), f(w0[idx]), f(U[idx])) if dc else ClampingMaxEffort(f(U[idx]))
    act = Actuator(wp.array(np.arange(m, dtype=np.uint32)), drive=drive, clamping=[clamp])
    s0, s1 = act.state(), act.state()
    cmd = rng.uniform(-0.5, 0.5, (40, m)).astype(np.float32)
    pos, vel = cmd[0].astype(np.float64), np.zeros(m)
    acc = np.where(a[idx] > 0, a[idx], 1.0) * dt * dt
    for k in range(40):
        q, qd = rng.uniform(-0.5, 0.5, m).astype(np.float32), rng.uniform(-4, 4, m).astype(np.float32)
        out = wp.zeros(m)
        ctl = {"joint_target_q": f(cmd[k]), "joint_target_qd": wp.zeros(m), "joint_f": out}
        act.step({"joint_q": f(q), "joint_qd": f(qd)}, ctl, s0, s1, dt=dt)
        s0, s1 = s1, s0
        p2, v2 = profile_step(np, cmd[k], pos, vel, acc)
        pos, vel = np.where(a[idx] > 0, p2, cmd[k]), np.where(a[idx] > 0, v2, 0.0)
        want = servo_torque(pos, q, qd, kp[idx], kd[idx], b[idx], U[idx], w0[idx], startup_torque=u0[idx],
                            backlash=bl[idx], encoder_offset=off[idx])
        # within a tick of the play's edge the drive scales before the clamp, the law after: not compared there
        g = play(pos - (q + off[idx]), bl[idx])[1]
        edge = (g > 0) & (g < 1)
        ramped += int(edge.sum())
        worst = max(worst, float(np.abs(out.numpy() - want)[~edge].max()))
print("RAMPED", ramped)
print("LAW", worst)
"""


def test_the_servo_drive_with_the_dc_motor_clamp_is_the_servo_law(servo_export):
    """``DriveServo`` + Newton's ``ClampingDCMotor`` (or ``ClampingMaxEffort``) in a ``newton.actuators.Actuator``
    against :func:`servo_torque` after :func:`profile_step` (numpy, float64), random gains, backlash, encoder offsets,
    startup torques and states over 40 steps. Bound 1e-4 N m (measured 4.4e-5; 3.8e-6 without startup torques):
    float32 arithmetic on torques of a few N m, goals carrying 40 steps of round-off, which the startup torque's
    ramp (up to 0.5 N m over one tick, 330 N m/rad) amplifies; states within a tick of the play's edge left out
    (the docstring's difference)."""
    _, _, _, out, _ = servo_export
    res = subprocess.run([sys.executable, "-c", _LAW, str(out)], cwd=REPO, capture_output=True, text=True,
                         env=_ENV, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    worst = float(res.stdout.split("LAW")[-1])
    print(f"servo law: max |tau - tau_numpy| {worst:.2e} N m;", res.stdout.split("LAW")[0].strip())
    assert worst < 1e-4


def test_plain_newton_reproduces_the_servo_replay(servo_export, tmp_path):
    """The round trip for servo drives: examples/calibrated_robot_newton.py in its own process (Newton, the export's
    ``servo_actuator.py`` and the residual component) against SolverReplay with the identified physics, the servo
    fields and the residual, on the held-out run.

    Tolerance 2e-3 rad mean, 6e-3 max over 0.6 s (measured 1.4e-3 and 4.0e-3): the two differ as for PD drives
    (MuJoCo C's implicitfast with a soft frictionloss against SolverReplay's, the servo's velocity terms explicit in
    the actuator and implicit in SolverReplay). The servo model's own effect (the same replay without dead band,
    startup torque, torque–speed line, profile, backlash and offset; measured 0.125 rad) is asserted 20 times the
    round-trip error, so an export that dropped any of it would fail."""
    import dataclasses

    from wresdyn.learn.network_file import load_residual
    from wresdyn.sim.physics import PhysicalParams
    from wresdyn.sim.rollout import replay_trajectories

    robot, data, run, out, data_path = servo_export
    saved = tmp_path / "plain.npz"
    res = subprocess.run([sys.executable, str(EXAMPLE), str(out), str(data_path), "--split", "heldout",
                          "--seconds", "0.6", "--save", str(saved)], cwd=REPO, capture_output=True, text=True,
                         env=_ENV, timeout=600)
    assert res.returncode == 0, res.stderr[-3000:]
    traj = data.split("heldout")[0]
    q_plain = np.load(saved)[traj.name]
    physics = PhysicalParams.load(run / "physics.json", robot)
    policy = load_residual(run / "policy.pt")
    ref = replay_trajectories(robot, [traj], data.rate_hz, policy, physics=physics)["residual"].q[0][:len(q_plain)]
    plain_servo = dataclasses.replace(physics, deadband=np.zeros(3), noload_speed=np.zeros(3), goal_accel=np.zeros(3),
                                      backlash=np.zeros(3), encoder_offset=np.zeros(3), startup_torque=np.zeros(3))
    no_servo = replay_trajectories(robot, [traj], data.rate_hz, policy, physics=plain_servo)["residual"].q[0][:len(ref)]
    diff = np.abs(q_plain - ref)
    effect = np.abs(no_servo - ref).mean()
    print(f"servo round trip {diff.mean():.2e} mean, {diff.max():.2e} max rad; servo model's effect {effect:.2e}")
    assert diff.mean() < 2e-3 and diff.max() < 6e-3, (diff.mean(), diff.max())
    assert effect > 20 * diff.mean()


def test_a_servo_robot_from_mjcf_names_the_conversion_step(tmp_path, capsys, monkeypatch):
    """The SO-101 (MJCF, servo drives from scenes/so101/servo.toml) where the converter cannot run: the export names
    the conversion to USD, in one line, and writes nothing (tests/export/test_convert.py exports it)."""
    monkeypatch.setenv("WRESDYN_USD_CONVERTER_PYTHON", str(tmp_path / "no-python"))
    from wresdyn.data.dataset import Dataset, Trajectory
    from wresdyn.robot.description import load_robot

    robot = load_robot(REPO / "scenes" / "so101" / "so101.xml", gains=REPO / "scenes" / "so101" / "servo.toml")
    assert robot.servo is not None
    z = np.zeros((3, robot.n_dof))
    ds = Dataset(list(robot.joint_names), 50.0, [Trajectory("t", "train", np.arange(3) / 50.0, z, z, z, z, z)],
                 str(robot.source), robot.source_sha256, {}, 0, {}, robot.gains_record())
    ds.save(tmp_path / "so101.npz")
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"data_path": str(tmp_path / "so101.npz")}))
    assert main(["export", str(run), "--out", str(tmp_path / "out"), "--physics-only", "--format", "usd"]) == 2
    err = capsys.readouterr().err.strip()
    assert "mujoco-usd-converter" in err and len(err.splitlines()) == 1
    assert not (tmp_path / "out").exists()


def test_a_damper_law_run_with_stiction_exports_and_says_so(servo_export, tmp_path):
    """A run identified under the damper friction law with a servo stiction and load friction: exit 0, the friction
    amplitudes as Newton's joint friction (without either) and ``export.json``'s notes naming the three changes."""
    import shutil

    from pxr import Usd

    robot, _, run, _, _ = servo_export
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    cfg = json.loads((copy / "config.json").read_text())
    (copy / "config.json").write_text(json.dumps({**cfg, "friction_kappa": 500.0}))
    p = _servo_physics(robot)
    p.stiction[1] = 0.07
    p.load_friction[1] = 0.12
    p.save(copy / "physics.json")
    assert main(["export", str(copy), "--out", str(tmp_path / "calibrated")]) == 0
    record = json.loads((tmp_path / "calibrated" / "export.json").read_text())
    assert record["friction_kappa"] == 500.0 and len(record["notes"]) == 3, record["notes"]
    assert "damper law" in record["notes"][0] and "kappa = 500" in record["notes"][0]
    assert record["notes"][1].startswith("elbow: servo stiction 0.07 N m dropped")
    assert record["notes"][2].startswith("elbow: servo load friction 0.12 x |drive torque| dropped")
    stage = Usd.Stage.Open(str(tmp_path / "calibrated" / "robot.usda"))
    got = [stage.GetPrimAtPath(f"/arm/joints/{n}").GetAttribute("newton:friction").Get() for n in robot.joint_names]
    np.testing.assert_allclose(got, p.friction, rtol=1e-6)
