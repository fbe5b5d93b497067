"""``wresdyn export`` of robots loaded from MJCF or URDF: converted to USD by the maintained converters (in
``.venv-usd``, ``scripts/setup.sh usd``), the layers over the converted file, read back by Newton's USD importer.

The SO-101 (MJCF, servo drives) and example-robot-data's UR5 (URDF) are exported with the nominal physics moved by
hand, so that every authored value differs from the robot file's.
"""

from __future__ import annotations

import json
import sysconfig
from pathlib import Path

import numpy as np
import pytest

from wresdyn.cli import main
from wresdyn.paths import REPO

SO101 = REPO / "scenes" / "so101" / "so101.xml"
SERVO = REPO / "scenes" / "so101" / "servo.toml"
UR5 = (Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
       / "ur_description" / "urdf" / "ur5_robot.urdf")
RATE = 50.0


def _moved(robot):
    """The robot file's physics with every exported field moved."""
    from wresdyn.sim.physics import PhysicalParams

    p = PhysicalParams.nominal(robot)
    p.kp = p.kp * 1.1 + 5.0
    p.kd = p.kd * 0.9 + 0.5
    p.armature = p.armature * 1.3 + 0.01
    p.damping = p.damping + 0.4
    p.friction = p.friction + 0.03
    p.effort = np.where(np.isfinite(p.effort), 0.8 * p.effort, 50.0)
    p.body_mass = p.body_mass * 1.05
    p.body_com = p.body_com + 0.004 * (p.body_mass > 0)[:, None]
    p.body_inertia = p.body_inertia * 1.07
    return p


def _export(tmp: Path, robot, q0: np.ndarray, steps: int = 40, rc: int = 0, config: dict | None = None,
            physics=None):
    """A physics-only run of ``robot`` on a recording of ``steps`` samples (a step command from ``q0``), exported
    (``wresdyn export`` exits ``rc``); ``config`` joins the run's config.json, ``physics`` (default the nominal
    moved by :func:`_moved`) its physics.json."""
    from wresdyn.data.dataset import Dataset, Trajectory

    n = robot.n_dof
    q = np.tile(q0, (steps, 1))
    cmd = q + 0.3 * np.sign(np.arange(n) % 2 - 0.5)
    z = np.zeros((steps, n))
    tr = Trajectory("t", "train", np.arange(steps) / RATE, q, z, z, cmd)
    ds = Dataset(list(robot.joint_names), RATE, [tr], str(robot.source), robot.source_sha256, {}, 0, {},
                 robot.gains_record())
    ds.save(tmp / "data.npz")
    run = tmp / "run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"data_path": str(tmp / "data.npz"), **(config or {})}))
    physics = _moved(robot) if physics is None else physics
    physics.save(run / "physics.json")
    assert main(["export", str(run), "--out", str(tmp / "out"), "--physics-only", "--format", "usd"]) == rc
    return physics, tr, tmp / "out"


def _check_read_back(cal, want, original):
    """``cal`` (robot.usda through Newton's importer) carries ``want`` (on ``original``), matched by name."""
    j = [list(original.joint_names).index(n) for n in cal.joint_names]
    assert sorted(cal.joint_names) == sorted(original.joint_names)
    for f in ("kp", "kd", "armature", "damping", "friction", "effort"):
        np.testing.assert_allclose(getattr(cal, f), getattr(want, f)[j], rtol=1e-5, atol=1e-7, err_msg=f)
    np.testing.assert_allclose(cal.lower, original.lower[j], atol=2e-7)
    np.testing.assert_allclose(cal.upper, original.upper[j], atol=2e-7)
    b = np.array([list(original.body_names).index(n) for n in cal.body_names])
    m = want.body_mass[b] > 0  # the layer authors bodies with mass; the URDF converter gives a massless link 1 g
    assert np.all(cal.body_mass[~m] <= 1e-3)
    np.testing.assert_allclose(cal.body_mass[m], want.body_mass[b[m]], rtol=1e-6)
    np.testing.assert_allclose(cal.body_com[m], want.body_com[b[m]], atol=1e-6)
    np.testing.assert_allclose(cal.body_inertia[m], want.body_inertia[b[m]],
                               atol=1e-6 * np.abs(want.body_inertia).max())
    assert not np.allclose(cal.body_mass[m], original.body_mass[b[m]])  # the layer did change the robot
    assert not np.allclose(cal.body_inertia[m], original.body_inertia[b[m]])
    lost = [n for n in original.body_names if n not in cal.body_names]
    assert all(original.body_mass[list(original.body_names).index(n)] == 0 for n in lost), lost


@pytest.fixture(scope="module")
def so101_export(tmp_path_factory):
    from wresdyn.robot.description import load_robot

    robot = load_robot(SO101, gains=SERVO)
    assert robot.servo is not None
    physics, tr, out = _export(tmp_path_factory.mktemp("so101"), robot, 0.5 * (robot.lower + robot.upper))
    return robot, physics, tr, out


def test_an_mjcf_robot_exports_usd_layers_over_its_conversion(so101_export):
    """The SO-101's export holds the converted USD under source/ and the same layers as a USD robot's; Newton loads
    robot.usda with the identified physics, the joints' limits and the servo drive."""
    from wresdyn.robot.description import load_robot

    robot, physics, _, out = so101_export
    assert {"robot.usda", "actuated.usda", "physics.json", "export.json", "servo_actuator.py"} <= {
        p.name for p in out.iterdir()}
    record = json.loads((out / "export.json").read_text())
    assert record["robot_file"] == str(robot.source) and record["robot_sha256"] == robot.source_sha256
    converted = out / record["converted"]
    assert converted.parent == out / "source" and "MuJoCo USD Converter" in converted.read_text()
    layer = (out / "robot.usda").read_text()
    assert f"@{record['converted']}@" in layer  # relative: the folder moves as one
    assert layer.count('token wresdyn:drive = "servo"') == robot.n_dof
    assert load_robot(out / "robot.usda", gains=SERVO).servo is not None
    cal = load_robot(out / "robot.usda")  # without the gains file, whose overrides would hide the authored values
    assert list(cal.joint_names) == list(robot.joint_names)
    _check_read_back(cal, physics, robot)


def test_the_converted_export_replays_like_the_mjcf_robot(so101_export):
    """The same commands on the MJCF robot with the identified physics and on the exported robot.usda with its
    own (read back) physics: the same motion, far closer than the physics change moves it."""
    from wresdyn.robot.description import load_robot
    from wresdyn.sim.physics import PhysicalParams
    from wresdyn.sim.rollout import replay_trajectories

    robot, physics, tr, out = so101_export
    read = PhysicalParams.nominal(load_robot(out / "robot.usda"))
    for f in ("deadband", "noload_speed", "goal_accel"):  # authored for the servo actuator, not read by the importer
        setattr(read, f, getattr(physics, f))
    cal = load_robot(out / "robot.usda", gains=SERVO)  # the servo drive's joints
    ref = replay_trajectories(robot, [tr], RATE, physics=physics)["residual"].q[0]
    got = replay_trajectories(cal, [tr], RATE, physics=read)["residual"].q[0]
    nominal = replay_trajectories(robot, [tr], RATE, physics=PhysicalParams.nominal(robot))["residual"].q[0]
    diff, effect = np.abs(got - ref), np.abs(nominal - ref).max()
    print(f"so101 converted replay {diff.mean():.2e} mean, {diff.max():.2e} max rad; physics change {effect:.2e}")
    assert np.abs(ref - tr.q[0]).max() > 0.1  # it moved
    assert diff.max() < 1e-6 and effect > 1e4 * diff.max(), (diff.max(), effect)  # measured 1.2e-7 rad


def test_the_so101_servo_model_with_the_damper_law_stiction_and_startup_torque_exports_as_usd(tmp_path):
    """The SO-101 servo model identified under the damper friction law, with stiction and startup torques: the USD
    export exits 0 with notes on the friction law and each dropped stiction, the actuators carry the startup torque,
    and the exported robot (read back, its startup torques from actuated.usda) replays close to the source model
    under the same law, 2e-3 rad max (measured 9.8e-4, 2.0e-4 mean over the 0.8 s step recording): all of it the
    dropped stiction, the source replayed without it is within 1e-6 rad (measured 3.0e-8), far below the startup
    torque's own effect (measured 4.7e-3 rad)."""
    import dataclasses

    from pxr import Usd

    from wresdyn.robot.description import load_robot
    from wresdyn.sim.physics import PhysicalParams
    from wresdyn.sim.rollout import replay_trajectories

    robot = load_robot(SO101, gains=SERVO)
    physics = _moved(robot)
    physics.stiction = np.full(robot.n_dof, 0.02)
    physics.startup_torque = np.full(robot.n_dof, 0.05)
    kappa = 800.0
    physics, tr, out = _export(tmp_path, robot, 0.5 * (robot.lower + robot.upper), config={"friction_kappa": kappa},
                               physics=physics)
    notes = json.loads((out / "export.json").read_text())["notes"]
    assert len(notes) == 1 + robot.n_dof and "damper law" in notes[0], notes
    assert all("servo stiction 0.02 N m dropped" in n for n in notes[1:])
    act = Usd.Stage.Open(str(out / "actuated.usda"))
    scope = f"{act.GetDefaultPrim().GetPath()}/wresdyn_actuators"
    u0 = np.array([act.GetPrimAtPath(f"{scope}/{n}").GetAttribute("newton:servoStartupTorque").Get()
                   for n in robot.joint_names])
    np.testing.assert_allclose(u0, physics.startup_torque, rtol=1e-6)
    read = PhysicalParams.nominal(load_robot(out / "robot.usda"))
    for f in ("deadband", "noload_speed", "goal_accel"):  # authored for the servo actuator, not read by the importer
        setattr(read, f, getattr(physics, f))
    read.startup_torque = u0
    cal = load_robot(out / "robot.usda", gains=SERVO)
    ref = replay_trajectories(robot, [tr], RATE, physics=physics, friction_kappa=kappa)["residual"].q[0]
    got = replay_trajectories(cal, [tr], RATE, physics=read, friction_kappa=kappa)["residual"].q[0]
    kept = replay_trajectories(robot, [tr], RATE, physics=dataclasses.replace(physics, stiction=0 * physics.stiction),
                               friction_kappa=kappa)["residual"].q[0]  # the source without what the notes drop
    no_u0 = replay_trajectories(cal, [tr], RATE, physics=dataclasses.replace(read, startup_torque=0 * u0),
                                friction_kappa=kappa)["residual"].q[0]
    diff, exact, effect = np.abs(got - ref), np.abs(got - kept).max(), np.abs(no_u0 - got).max()
    print(f"so101 damper-law export replay {diff.mean():.2e} mean, {diff.max():.2e} max rad; without the stiction "
          f"{exact:.2e}; startup torque's effect {effect:.2e}")
    assert np.abs(ref - tr.q[0]).max() > 0.1  # it moved
    assert diff.max() < 2e-3 and diff.max() > 1e3 * exact, (diff.max(), exact)  # the stiction's loss is real
    assert exact < 1e-6 and effect > 1e3 * exact, (exact, effect)


def test_a_urdf_robot_exports_usd_layers_over_its_conversion(tmp_path):
    """example-robot-data's UR5 (URDF, Collada meshes): the massless frames the converter folds away are dropped,
    every body with mass keeps its identified parameters, and the exported robot replays like the URDF one."""
    from wresdyn.robot.description import load_robot
    from wresdyn.sim.physics import PhysicalParams
    from wresdyn.sim.rollout import replay_trajectories

    robot = load_robot(UR5)
    physics, tr, out = _export(tmp_path, robot, np.zeros(robot.n_dof), steps=20)
    record = json.loads((out / "export.json").read_text())
    assert record["robot_file"] == str(UR5) and (out / record["converted"]).is_file()
    cal = load_robot(out / "robot.usda")
    assert len(cal.body_names) < len(robot.body_names)  # world, base, tool0: fixed massless frames
    _check_read_back(cal, physics, robot)
    ref = replay_trajectories(robot, [tr], RATE, physics=physics)["residual"].q[0]
    got = replay_trajectories(cal, [tr], RATE, physics=PhysicalParams.nominal(cal))["residual"].q[0]
    diff = np.abs(got - ref).max()
    print(f"ur5 converted replay {diff:.2e} max rad over {np.abs(ref - tr.q[0]).max():.2f} rad of motion")
    # measured 1.0e-4 rad: the converter's 1 g on the massless ee_link (the arm's tip); with that gram on the URDF
    # robot too the two agree to 5e-10 rad
    assert np.abs(ref - tr.q[0]).max() > 0.5 and diff < 2e-4, diff


def test_a_missing_converter_is_one_line_and_writes_nothing(tmp_path, monkeypatch, capsys):
    """A converter interpreter that does not exist: one line naming the converter, exit non-zero, no folder."""
    from wresdyn.robot.description import load_robot

    monkeypatch.setenv("WRESDYN_USD_CONVERTER_PYTHON", str(tmp_path / "no-python"))
    robot = load_robot(UR5)
    capsys.readouterr()
    _export(tmp_path, robot, np.zeros(robot.n_dof), steps=3, rc=2)
    err = capsys.readouterr().err.strip()
    assert "urdf-usd-converter" in err and len(err.splitlines()) == 1, err
    assert not (tmp_path / "out").exists() and not list(tmp_path.glob(".out.*"))
