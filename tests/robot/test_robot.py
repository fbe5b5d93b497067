"""Robot loading: the project humanoid's description, gains overrides, and one-line errors on bad files."""

import sys
from pathlib import Path

import numpy as np
import pytest

from wresdyn.robot.description import DEFAULT_ROBOT, RobotError, load_robot

LEG = ["hip_yaw", "hip_roll", "hip_pitch", "knee", "ankle_pitch", "ankle_roll"]
ARM = ["shoulder_pitch", "shoulder_roll", "shoulder_yaw", "elbow"]


def test_humanoid_description(humanoid):
    r = humanoid
    expected = [f"left_{j}" for j in LEG] + [f"right_{j}" for j in LEG] + ["waist_yaw"]
    expected += [f"left_{j}" for j in ARM] + [f"right_{j}" for j in ARM]
    assert r.joint_names == expected
    assert r.n_dof == 21 and r.base == "fixed" and r.body_names[0] == "pelvis"
    assert 30.0 <= r.body_mass.sum() <= 40.0
    assert set(r.frames) == {"left_sole", "right_sole"}
    assert np.all(r.lower < r.upper) and np.all(np.isfinite(r.lower))
    legs = [r.joint_names.index(f"{s}_{j}") for s in ("left", "right") for j in ("hip_pitch", "hip_roll", "knee")]
    # USD stores angular gains per degree in float32: allow that round-off around the bounds
    assert np.all((r.kp[legs] >= 100.0 - 1e-3) & (r.kp[legs] <= 200.0 + 1e-3))
    ankles_arms = [i for i, n in enumerate(r.joint_names) if "ankle" in n or any(a in n for a in ARM)]
    assert np.all((r.kp[ankles_arms] >= 20.0 - 1e-3) & (r.kp[ankles_arms] <= 60.0 + 1e-3))
    assert np.all(r.armature > 0.0) and np.all(np.isfinite(r.effort)) and np.all(r.kd > 0.0)
    # inertias are physical: symmetric positive definite and satisfying the triangle inequality
    for inertia in r.body_inertia:
        w = np.linalg.eigvalsh(inertia)
        assert w.min() > 0.0 and w[0] + w[1] >= w[2] - 1e-12


def test_scene_generator_is_reproducible(tmp_path):
    """The committed USD is what scenes/make_humanoid.py writes."""
    sys.path.insert(0, str(DEFAULT_ROBOT.parent))
    import make_humanoid

    out = tmp_path / "humanoid.usda"
    make_humanoid.write(out)
    a = load_robot(out)
    b = load_robot(DEFAULT_ROBOT)
    assert a.joint_names == b.joint_names
    for field in ("kp", "kd", "lower", "upper", "armature", "effort", "body_mass", "body_inertia", "joint_X_p"):
        np.testing.assert_array_equal(getattr(a, field), getattr(b, field))


def test_gains_override_by_pattern(tmp_path):
    cfg = tmp_path / "gains.toml"
    cfg.write_text('[[joint]]\nmatch = "*"\nkp = 50.0\nkd = 1.5\n[[joint]]\nmatch = "*_knee"\nkp = 300.0\narmature = 0.05\n')
    r = load_robot(DEFAULT_ROBOT, gains=cfg)
    knee = [i for i, n in enumerate(r.joint_names) if n.endswith("_knee")]
    other = [i for i in range(r.n_dof) if i not in knee]
    assert np.all(r.kp[knee] == 300.0) and np.all(r.kp[other] == 50.0) and np.all(r.kd == 1.5)
    assert np.allclose(r.armature[knee], 0.05)


def test_robot_without_gains_gets_clear_message(quadruped):
    bare = load_robot("newton:quadruped.urdf")
    assert np.all(bare.kp == 0.0)
    with pytest.raises(RobotError, match=r"no PD gains.*--gains"):
        bare.check_gains()
    quadruped.check_gains()  # the inline config supplies them


@pytest.mark.parametrize(
    "gains, match",
    [
        ('[[joint]]\nmatch = "nope_*"\nkp = 1.0\n', "matches no"),
        ('[[joint]]\nmatch = "*"\nstiffness = 1.0\n', "unknown key"),
        ('[[joint]]\nmatch = "*"\nkp = -1.0\n', "must be >= 0"),
        ("[[joint]\nmatch = ", "malformed TOML"),
        ('[[joint]]\nkp = 1.0\n', "needs a match"),
    ],
)
def test_bad_gains_config(tmp_path, gains, match):
    cfg = tmp_path / "gains.toml"
    cfg.write_text(gains)
    with pytest.raises(RobotError, match=match):
        load_robot(DEFAULT_ROBOT, gains=cfg)


def _usd(tmp_path, body: str) -> Path:
    p = tmp_path / "robot.usda"
    p.write_text('#usda 1.0\n(\n    upAxis = "Z"\n    metersPerUnit = 1\n)\n' + body)
    return p


def test_bad_robot_files(tmp_path):
    with pytest.raises(RobotError, match="not found"):
        load_robot(tmp_path / "missing.usda")
    bad = tmp_path / "robot.txt"
    bad.write_text("hello")
    with pytest.raises(RobotError, match="unknown robot file type"):
        load_robot(bad)
    with pytest.raises(RobotError, match="cannot parse USD"):
        load_robot(_usd(tmp_path, "def Xform \"a\" { this is not usd }\n"))
    with pytest.raises(RobotError, match="cannot parse URDF"):
        (tmp_path / "r.urdf").write_text("<robot name='r'><link name='a'>")
        load_robot(tmp_path / "r.urdf")
    empty = _usd(tmp_path, 'def Xform "world" {}\n')
    with pytest.raises(RobotError, match="no articulation"):
        load_robot(empty)
    # a single rigid body and no joint is not an articulation either
    lone = _usd(tmp_path, 'def Cube "box" (prepend apiSchemas = ["PhysicsRigidBodyAPI", "PhysicsCollisionAPI", "PhysicsMassAPI"]) { float physics:mass = 1 }\n')
    with pytest.raises(RobotError, match="no articulation"):
        load_robot(lone)
    # newton's MJCF humanoid has multi-axis hinge groups, imported as D6 joints
    with pytest.raises(RobotError, match="unsupported joint type D6"):
        load_robot("newton:nv_humanoid.xml")


def test_cli_errors_are_one_line_with_exit_2(tmp_path, capsys):
    """Through main() in this process (a process of its own loads Newton and torch again before the check, 6 s of
    CPU each); the executable's exit status and stderr: tests/ppo/test_trainer.py's refusals, one process each."""
    from wresdyn.cli import main

    for target in (str(tmp_path / "missing.usda"), "newton:nv_humanoid.xml"):
        capsys.readouterr()
        assert main(["inspect", target]) == 2
        out = capsys.readouterr()
        lines = [ln for ln in out.err.splitlines() if ln.startswith("wresdyn")]
        assert len(lines) == 1 and "error:" in lines[0] and target.split(":")[-1] in lines[0] and out.out == ""


def test_mjcf_and_urdf_load_through_newton(quadruped):
    ant = load_robot("newton:nv_ant.xml", gains={"joint": [{"match": "*", "kp": 20.0, "kd": 0.5}]})
    assert ant.n_dof == 8 and np.allclose(ant.armature, 0.01)  # armature read from the MJCF defaults
    assert ant.joint_names[:2] == ["hip_1", "ankle_1"] and np.all(ant.kp == 20.0)
    assert quadruped.n_dof == 12 and quadruped.joint_names[0] == "LF_HAA"
    floating = load_robot("newton:quadruped.urdf", base="floating")
    assert floating.joint_type[0] == "free" and floating.n_dof == 12


def test_robot_pickles_as_its_load_call(humanoid):
    """Parallel workers receive robots by pickle: the copy is the same description, gains overrides included."""
    import pickle

    copy = pickle.loads(pickle.dumps(humanoid))
    assert copy.joint_names == humanoid.joint_names and np.array_equal(copy.kp, humanoid.kp)
    tuned = load_robot(DEFAULT_ROBOT, gains={"joint": [{"match": "*_knee", "kp": 123.0}]})
    again = pickle.loads(pickle.dumps(tuned))
    assert np.array_equal(again.kp, tuned.kp) and 123.0 in again.kp


def test_unpickling_a_robot_whose_file_changed_fails(tmp_path):
    import pickle

    path = tmp_path / "humanoid.usda"
    path.write_text(DEFAULT_ROBOT.read_text())
    blob = pickle.dumps(load_robot(path))
    path.write_text(DEFAULT_ROBOT.read_text() + "\n# edited\n")
    with pytest.raises(RobotError, match="changed since it was loaded"):
        pickle.loads(blob)


_WORLD_LINK_URDF = """<robot name="arm">
  <link name="world"/>
  <link name="world_link"><inertial><mass value="1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <link name="forearm"><inertial><origin xyz="0 0 0.2"/><mass value="1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="base_fixed" type="fixed"><parent link="world"/><child link="world_link"/></joint>
  <joint name="elbow" type="revolute"><parent link="world_link"/><child link="forearm"/><axis xyz="0 1 0"/>
    <limit lower="-1" upper="1" effort="10" velocity="1"/></joint>
</robot>
"""


def test_mujoco_renames_a_world_body(tmp_path):
    """A URDF whose root link is ``world`` (UR5, Panda in example-robot-data) builds in MuJoCo, which reserves the
    name for its own world body: the link becomes ``world_link``, here ``world_link_1`` as that name is taken."""
    import mujoco

    from wresdyn.robot.mujoco_model import build_mujoco, mujoco_body_names

    assert mujoco_body_names(["world", "base"]) == ["world_link", "base"]
    assert mujoco_body_names(["world", "world_link"]) == ["world_link_1", "world_link"]
    (tmp_path / "arm.urdf").write_text(_WORLD_LINK_URDF)
    robot = load_robot(tmp_path / "arm.urdf", gains={"joint": [{"match": "*", "kp": 10.0, "kd": 1.0}]})
    m = build_mujoco(robot)
    names = [mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_BODY, b) for b in range(m.nbody)]
    assert names[0] == "world" and "world_link_1" in names and len(set(names)) == len(names)
    assert m.nu == robot.n_dof == 1
