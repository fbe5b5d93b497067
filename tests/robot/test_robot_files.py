"""Robot files as they come: effort limits the importers leave out (MJCF actuator force range, USD mjc:
attributes), placeholder effort limits refused in one line, the gains config travelling with a dataset, URDFs with
Collada meshes behind package:// URIs (resolved in the description's tree or --package-path), and bad input (no
gains, a gains pattern matching no joint, a model that diverges in its first steps) refused in one line with exit
code 2 and nothing written."""

from __future__ import annotations

import json
import os
import pickle
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest

from wresdyn.cli import main
from wresdyn.data.dataset import Dataset, DatasetError, load_dataset, read_header
from wresdyn.data.loading import load_data
from wresdyn.robot.description import PLACEHOLDER_EFFORT, RobotError, load_robot
from wresdyn.robot.mujoco_model import build_mujoco

KP_ONLY = {"joint": [{"match": "*", "kp": 20.0, "kd": 0.5}]}
"""Gains for newton's nv_ant.xml: its motors state no force range, so the effort limits stay placeholders."""


def _raw_header(path) -> dict:
    """The header JSON exactly as stored (no defaults filled in)."""
    with np.load(path, allow_pickle=False) as z:
        return json.loads(z["header"].tobytes().decode("utf-8"))


def _one_line(capsys) -> str:
    err = [ln for ln in capsys.readouterr().err.splitlines() if ln.strip()]
    assert len(err) == 1, err
    return err[0]


def test_placeholder_effort_is_refused_in_one_line():
    ant = load_robot("newton:nv_ant.xml", gains=KP_ONLY)
    assert ant.placeholder_effort() == ant.joint_names and np.all(ant.effort >= PLACEHOLDER_EFFORT)
    ant.check_gains()  # the gains are there: only the effort is missing
    with pytest.raises(RobotError) as e:
        ant.check_replay()
    msg = str(e.value)
    assert "\n" not in msg and "effort" in msg and "--gains" in msg and "hip_1" in msg
    # an effort the gains config states is taken as stated, even a huge one
    stated = load_robot("newton:nv_ant.xml", gains={"joint": [{**KP_ONLY["joint"][0], "effort": 1e6}]})
    assert stated.placeholder_effort() == []
    stated.check_replay()
    # files that state their limits pass as before
    quadruped = load_robot("newton:quadruped.urdf", gains="examples/gains/quadruped.toml")
    assert quadruped.placeholder_effort() == [] and np.all(quadruped.effort == 80.0)


def test_inspect_flags_placeholder_effort_and_collect_refuses_it(tmp_path, capsys):
    gains = tmp_path / "ant.toml"
    gains.write_text('[[joint]]\nmatch = "*"\nkp = 20.0\nkd = 0.5\n')
    assert main(["inspect", "newton:nv_ant.xml", "--gains", str(gains), "--seconds", "0.04"]) == 0
    out = capsys.readouterr().out
    assert "note" in out.splitlines()[1] and out.count("effort: placeholder") == 8
    assert "warning: 8 of 8 joints have no effort limit" in out and "PD replay" in out
    assert main(["collect", "--robot", "newton:nv_ant.xml", "--gains", str(gains), "--out", str(tmp_path / "o")]) == 2
    line = _one_line(capsys)
    assert line.startswith("wresdyn collect: error:") and "effort" in line and "--gains" in line
    assert not (tmp_path / "o").exists()


def test_mjcf_actuator_force_range_is_read(tmp_path):
    """Newton's MJCF importer reads a position actuator's kp and kv but not its force range (nor a motor's):
    wresdyn takes |gear| * max|forcerange| from MuJoCo's compiled model, the tighter of it and the joint's own
    actuatorfrcrange."""
    xml = tmp_path / "arm.xml"
    xml.write_text("""<mujoco><default><position kp="40" kv="2"/></default><worldbody><body name="base">
      <geom type="box" size="0.05 0.05 0.05" mass="1"/>
      <body name="a"><joint name="j1" type="hinge" axis="0 1 0" range="-1 1"/>
        <geom type="capsule" size="0.02" fromto="0 0 0 0.2 0 0" mass="0.5"/>
        <body name="b" pos="0.2 0 0"><joint name="j2" type="hinge" axis="0 1 0" range="-1 1" actuatorfrcrange="-4 4"/>
          <geom type="capsule" size="0.02" fromto="0 0 0 0.2 0 0" mass="0.3"/>
          <body name="c" pos="0.2 0 0"><joint name="j3" type="hinge" axis="0 1 0" range="-1 1"/>
            <geom type="capsule" size="0.02" fromto="0 0 0 0.1 0 0" mass="0.1"/></body></body></body>
      </body></worldbody><actuator><position joint="j1" forcerange="-3 3"/>
      <motor joint="j2" gear="2" forcerange="-5 5"/><position joint="j3"/></actuator></mujoco>""")
    r = load_robot(xml)
    assert r.joint_names == ["j1", "j2", "j3"]
    np.testing.assert_allclose(r.kp, [40.0, 0.0, 40.0])
    np.testing.assert_allclose(r.effort[:2], [3.0, 4.0])  # j2: min(joint's 4, motor's 2 * 5)
    assert r.placeholder_effort() == ["j3"]


def _mjc_usd(path):
    """A three-link arm as a USD converted from MJCF keeps it: joint a1 has only mjc:actuatorfrcrange, joint a2
    only an MjcActuator prim (force range, position-shaped gain and bias), joint a3 nothing."""
    from pxr import Gf, Sdf, Usd, UsdGeom, UsdPhysics

    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdPhysics.Scene.Define(stage, "/physicsScene")
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/arm").GetPrim())
    for i, name in enumerate(("base", "l1", "l2", "l3")):
        body = UsdGeom.Xform.Define(stage, f"/arm/{name}")
        body.AddTranslateOp().Set(Gf.Vec3d(0.2 * i, 0.0, 1.0))
        UsdPhysics.RigidBodyAPI.Apply(body.GetPrim())
        mass = UsdPhysics.MassAPI.Apply(body.GetPrim())
        mass.CreateMassAttr(1.0)
        mass.CreateDiagonalInertiaAttr(Gf.Vec3f(0.01, 0.01, 0.01))
        if i == 0:
            UsdPhysics.ArticulationRootAPI.Apply(body.GetPrim())
            fixed = UsdPhysics.FixedJoint.Define(stage, "/arm/joints/root")
            fixed.CreateBody1Rel().SetTargets(["/arm/base"])
            fixed.CreateLocalPos0Attr(Gf.Vec3f(0.0, 0.0, 1.0))
            continue
        joint = UsdPhysics.RevoluteJoint.Define(stage, f"/arm/joints/a{i}")
        joint.CreateBody0Rel().SetTargets([f"/arm/{('base', 'l1', 'l2')[i - 1]}"])
        joint.CreateBody1Rel().SetTargets([f"/arm/{name}"])
        joint.CreateLocalPos0Attr(Gf.Vec3f(0.2, 0.0, 0.0))
        joint.CreateLocalPos1Attr(Gf.Vec3f(0.0, 0.0, 0.0))
        joint.CreateAxisAttr("Y")
        joint.CreateLowerLimitAttr(-60.0)
        joint.CreateUpperLimitAttr(60.0)
    jp = stage.GetPrimAtPath("/arm/joints/a1")
    jp.CreateAttribute("mjc:actuatorfrcrange:min", Sdf.ValueTypeNames.Double).Set(-7.0)
    jp.CreateAttribute("mjc:actuatorfrcrange:max", Sdf.ValueTypeNames.Double).Set(7.0)
    act = stage.DefinePrim("/arm/actuators/a2", "MjcActuator")
    act.CreateRelationship("mjc:target").SetTargets(["/arm/joints/a2"])
    act.CreateAttribute("mjc:forceRange:min", Sdf.ValueTypeNames.Double).Set(-2.5)
    act.CreateAttribute("mjc:forceRange:max", Sdf.ValueTypeNames.Double).Set(2.5)
    act.CreateAttribute("mjc:gainPrm", Sdf.ValueTypeNames.DoubleArray).Set([30.0] + [0.0] * 9)
    act.CreateAttribute("mjc:biasPrm", Sdf.ValueTypeNames.DoubleArray).Set([0.0, -30.0, -1.5] + [0.0] * 7)
    stage.GetRootLayer().Save()
    return path


def test_usd_mjc_attributes_are_read(tmp_path):
    r = load_robot(_mjc_usd(tmp_path / "arm.usda"))
    assert r.joint_names == ["a1", "a2", "a3"]
    np.testing.assert_allclose(r.effort[:2], [7.0, 2.5])
    np.testing.assert_allclose([r.kp[1], r.kd[1]], [30.0, 1.5])
    assert r.kp[0] == 0.0 and r.placeholder_effort() == ["a3"]
    fixed = load_robot(tmp_path / "arm.usda", gains={"joint": [{"match": "*", "kp": 10.0, "kd": 1.0},
                                                               {"match": "a3", "effort": 1.0}]})
    fixed.check_replay()
    np.testing.assert_allclose(fixed.effort, [7.0, 2.5, 1.0])


def test_gains_travel_with_the_dataset(tmp_path, capsys):
    """collect --gains stores the parsed config in the header; load_data re-applies it; an explicit gains
    argument replaces it (with a warning); a dataset without gains has no header field and loads as before."""
    gains = tmp_path / "quad.toml"
    gains.write_text('[[joint]]\nmatch = "*"\nkp = 60.0\nkd = 2.5\narmature = 0.02\n'
                     '[[joint]]\nmatch = "*_KFE"\nkp = 90.0\n')
    out = tmp_path / "q"
    assert main(["collect", "--robot", "newton:quadruped.urdf", "--gains", str(gains), "--train", "1",
                 "--validation", "0", "--heldout", "1", "--ood", "1", "--duration", "0.2", "--no-gap",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "joint-space excitation" in text and "[3/3]" in text
    header = read_header(out / "dataset.npz")
    assert header["gains"] == {"file": str(gains), "config": {"joint": [
        {"match": "*", "kp": 60.0, "kd": 2.5, "armature": 0.02}, {"match": "*_KFE", "kp": 90.0}]}}
    assert header["meta"]["excitation"]["mode"] == "joint"
    ds, robot = load_data(str(out / "dataset.npz"))
    knee = [i for i, n in enumerate(robot.joint_names) if n.endswith("_KFE")]
    assert np.all(robot.kp[knee] == 90.0) and np.all(np.delete(robot.kp, knee) == 60.0) and np.all(robot.kd == 2.5)
    assert ds.gains == header["gains"]
    with pytest.warns(UserWarning, match="instead of the one stored"):
        _, other = load_data(str(out / "dataset.npz"), gains="examples/gains/quadruped.toml")
    assert np.all(other.kp[knee] == 100.0)
    # round trip keeps the field; a dataset without gains writes none and reads None
    ds.save(tmp_path / "again.npz")
    assert load_dataset(tmp_path / "again.npz").gains == ds.gains
    plain = Dataset(ds.joint_names, ds.rate_hz, ds.trajectories, ds.robot_file, ds.robot_sha256, {}, None, {})
    assert plain.gains is None and plain.gains_config is None
    plain.save(tmp_path / "plain.npz")
    assert "gains" not in _raw_header(tmp_path / "plain.npz") and read_header(tmp_path / "plain.npz")["gains"] is None
    assert load_dataset(tmp_path / "plain.npz").gains is None
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(RobotError, match="no PD gains"):  # the quadruped file has none
            load_data(str(tmp_path / "plain.npz"))
    # a malformed gains record is refused in one line
    bad = Dataset(ds.joint_names, ds.rate_hz, ds.trajectories, ds.robot_file, ds.robot_sha256, gains={"config": 1})
    with pytest.raises(DatasetError, match="gains must be null"):
        bad.save(tmp_path / "bad.npz")


def test_shipped_dataset_has_no_gains_and_loads():
    from wresdyn.paths import DEFAULT_DATASET

    assert "gains" not in _raw_header(DEFAULT_DATASET) and read_header(DEFAULT_DATASET)["gains"] is None
    assert load_dataset(DEFAULT_DATASET).gains is None


def _erd_robots() -> Path:
    """example-robot-data's robots folder (a dev dependency: its URDFs name Collada meshes by package:// URI); the
    cmeel wheel installs it under site-packages/cmeel.prefix."""
    import sysconfig

    robots = Path(sysconfig.get_paths()["purelib"]) / "cmeel.prefix" / "share" / "example-robot-data" / "robots"
    if not robots.is_dir():
        pytest.skip("example-robot-data is not installed")
    return robots


def _mesh_shapes(robot) -> int:
    """Mesh shapes of the robot's Newton builder that hold vertices (a mesh that failed to load is not added)."""
    import newton

    return sum(1 for t, src in zip(robot.builder.shape_type, robot.builder.shape_source)
               if int(t) == int(newton.GeoType.MESH) and src is not None and len(src.vertices) > 0)


MINI = """<robot name="mini">
  <link name="base"><inertial><mass value="1.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/>
    </inertial></link>
  <link name="arm"><inertial><origin xyz="0 0 -0.1"/><mass value="0.5"/>
      <inertia ixx="0.002" iyy="0.002" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><geometry><mesh filename="package://mini_description/meshes/base.dae"/></geometry></visual>
    <collision><geometry><mesh filename="package://mini_description/meshes/wrist3.stl"/></geometry></collision></link>
  <joint name="hinge" type="revolute"><parent link="base"/><child link="arm"/><axis xyz="0 1 0"/>
    <limit lower="-1.5" upper="1.5" velocity="3.0"/></joint>
</robot>
"""
"""A one-joint arm whose meshes (Collada visual, STL collision) are package:// URIs; its joint states neither gains
nor an effort limit."""


def _mini_package(root: Path) -> Path:
    """``root/mini_description/{meshes,urdf}`` with meshes copied from example-robot-data's UR5; the URDF's path."""
    ur5 = _erd_robots() / "ur_description" / "meshes" / "ur5"
    (root / "mini_description" / "meshes").mkdir(parents=True)
    shutil.copy(ur5 / "visual" / "base.dae", root / "mini_description" / "meshes")
    shutil.copy(ur5 / "collision" / "wrist3.stl", root / "mini_description" / "meshes")
    (root / "mini_description" / "urdf").mkdir()
    urdf = root / "mini_description" / "urdf" / "mini.urdf"
    urdf.write_text(MINI)
    return urdf


def test_ur5_with_collada_meshes_loads(capsys):
    urdf = _erd_robots() / "ur_description" / "urdf" / "ur5_robot.urdf"
    assert ".dae" in urdf.read_text() and "package://example-robot-data/" in urdf.read_text()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ur5 = load_robot(urdf)
    # Newton warns and drops a mesh it cannot find or read: none may be dropped
    assert not [w for w in caught if "resolve" in str(w.message) or "exist" in str(w.message)], caught
    assert ur5.n_dof == 6 and ur5.joint_names[0] == "shoulder_pan_joint"
    assert _mesh_shapes(ur5) >= 14  # 7 Collada visuals (some hold several meshes) + 7 STL collision meshes
    build_mujoco(ur5)  # its link "world" is the MuJoCo body world_link (MuJoCo's world keeps its name)
    ur5.check_effort()  # the URDF states its effort limits (150 / 28 N*m)
    # inspect lists a robot file without gains, says how to add them and skips the PD check it cannot run
    assert main(["inspect", str(urdf)]) == 0
    out = capsys.readouterr().out
    assert "6 actuated joints" in out and "shoulder_pan_joint" in out and "PD replay check skipped" in out
    assert "warning: 6 of 6 joints have no PD gains" in out and "--gains" in out


def test_package_uri_resolves_in_the_tree_and_on_the_package_path(tmp_path, capsys, monkeypatch):
    urdf = _mini_package(tmp_path / "ws")
    mini = load_robot(urdf)  # mini_description is a folder above the URDF
    assert _mesh_shapes(mini) >= 2
    # the same file away from its package: found only through --package-path (or ROS_PACKAGE_PATH)
    alone = tmp_path / "elsewhere" / "mini.urdf"
    alone.parent.mkdir()
    shutil.copy(urdf, alone)
    assert main(["inspect", str(alone), "--floating"]) == 2
    line = _one_line(capsys)
    assert line.startswith("wresdyn inspect: error:") and "package://mini_description/meshes/base.dae" in line
    assert str(alone.parent) in line and "--package-path" in line
    assert main(["--package-path", str(tmp_path / "ws"), "inspect", str(alone), "--floating"]) == 0
    assert "1 actuated joints" in capsys.readouterr().out
    assert main(["--package-path", str(tmp_path / "missing"), "inspect", str(alone), "--floating"]) == 2
    assert "not a folder" in _one_line(capsys)
    roots = f"{tmp_path / 'nothing_here'}{os.pathsep}{tmp_path / 'ws'}"
    (tmp_path / "nothing_here").mkdir()
    found = load_robot(alone, base="floating", package_path=roots)
    assert _mesh_shapes(found) >= 2
    # a worker process (parallel ablation) loads the file again with the same roots
    assert _mesh_shapes(pickle.loads(pickle.dumps(found))) >= 2
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ws"))  # ROS's own variable serves as well
    assert _mesh_shapes(load_robot(alone, base="floating")) >= 2
    monkeypatch.delenv("ROS_PACKAGE_PATH")
    # a relative mesh path that names no file is refused too, not dropped
    broken = tmp_path / "elsewhere" / "broken.urdf"
    broken.write_text(MINI.replace("package://mini_description/meshes/base.dae", "meshes/base.dae"))
    with pytest.raises(RobotError, match="mesh 'meshes/base.dae' not found"):
        load_robot(broken, package_path=[tmp_path / "ws"])


def test_robot_without_gains_is_refused_naming_the_joint(tmp_path, capsys):
    urdf = _mini_package(tmp_path / "ws")
    out = tmp_path / "o"
    assert main(["collect", "--robot", str(urdf), "--train", "1", "--validation", "0", "--heldout", "0", "--ood",
                 "0", "--duration", "0.2", "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert "hinge" in line and "no PD gains" in line and "no effort limit" in line
    assert '[[joint]] match = "hinge" kp = ' in line and "effort = " in line and "--gains" in line
    assert not out.exists()


def test_gains_naming_a_missing_joint_writes_nothing(tmp_path, capsys):
    gains = tmp_path / "typo.toml"
    gains.write_text('[[joint]]\nmatch = "slider_to_kart"\nkp = 100.0\nkd = 5.0\n')
    out = tmp_path / "o"
    assert main(["collect", "--robot", "newton:cartpole.urdf", "--gains", str(gains), "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert "slider_to_kart" in line and "matches no 1-DoF joint" in line and str(gains) in line
    assert not out.exists()


ABSURD = '[[joint]]\nmatch = "*"\nkp = 1e9\nkd = 1.0\neffort = 1e9\n'
"""Gains no explicit PD step survives: a stiffness of 1e9 N*m/rad on the cartpole's light links, unsaturated."""


def test_a_diverging_model_is_refused_by_collect_and_fit(tmp_path, capsys):
    absurd = tmp_path / "absurd.toml"
    absurd.write_text(ABSURD)
    short = ["--train", "1", "--validation", "0", "--heldout", "0", "--ood", "0", "--duration", "0.2"]
    out = tmp_path / "o"
    assert main(["collect", "--robot", "newton:cartpole.urdf", "--gains", str(absurd), *short, "--out", str(out)]) == 2
    line = _one_line(capsys)
    assert "MuJoCo real robot diverges" in line and "joint pole1_to_pole2" in line and "kp" in line
    assert not out.exists()
    data = tmp_path / "d"
    assert main(["collect", "--robot", "newton:cartpole.urdf", "--gains", "examples/gains/cartpole.toml", *short,
                 "--no-gap", "--out", str(data)]) == 0
    capsys.readouterr()
    run = tmp_path / "fit"
    with pytest.warns(UserWarning, match="instead of the one stored"):
        code = main(["fit", str(data / "dataset.npz"), "--gains", str(absurd), "--model", "network", "--iterations",
                     "1", "--windows", "1", "--out", str(run)])
    assert code == 2
    line = _one_line(capsys)
    assert line.startswith("wresdyn fit: error:") and "Newton replay" in line and "diverges" in line
    assert "joint pole" in line
    assert not run.exists()
    # the same checks pass the robot with its real gains, from rest and from the data's first sample
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.sim.first_steps import check_mujoco, check_newton

    ds, cartpole = load_data(str(data / "dataset.npz"))
    check_mujoco(RealRobot(cartpole, Mismatch.load("data/mismatch_default.toml"), ds.rate_hz))
    first = ds.trajectories[0]
    check_newton(cartpole, ds.rate_hz, first.q[0], first.qd[0], first.q_cmd)
