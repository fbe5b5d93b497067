"""LeRobot datasets without a mapping file (:mod:`wresdyn.data.lerobot`): the shipped fixture written by LeRobot's
own writer (benchmarks/real/so101_lerobot_fixture.py) imports to the SAGE runs it was made from, LeRobot's units convert
as its motor bus defines them, and every missing piece or bad input is a one-line error that writes nothing."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
from test_importers import SO101_GRIPPER, SO101_JOINTS, FakeRobot, _episodes, _write_lerobot

from wresdyn.data.dataset import DatasetError, load_dataset
from wresdyn.data.importers import import_runs, read_runs
from wresdyn.data.lerobot import LeRobotUnits, load_calibration
from wresdyn.data.logs import LogMap

REPO = Path(__file__).resolve().parents[2]
FIXTURE = REPO / "tests" / "data" / "lerobot_so101"
CALIBRATION = REPO / "tests" / "data" / "lerobot_so101_calibration.json"
SAGE_RUNS = ("multisine", "prbs_excitation", "step_response", "pick_place")
"""The SAGE run (data/so101/logs) each fixture episode was made from, in episode order."""
FLOAT32_RAD = 1e-6
"""The fixture stores LeRobot's units as float32 (7 significant digits of at most 100 units of a range of at most
±2.8 rad): what a round trip through it keeps of a position [rad]."""
RATE = 500.0


def _robot():
    return FakeRobot(SO101_JOINTS)


def test_fixture_imports_to_the_sage_runs_it_was_made_from():
    """Range units and LeRobot's calibration file back to radians: the positions and commands equal those of the
    SAGE import with its hand-written map (data/so101/map.toml), the gripper included (0..100 onto its range)."""
    units = LeRobotUnits.load(CALIBRATION, "range")
    ds = import_runs([FIXTURE], _robot(), RATE, lerobot=units)
    assert [tr.name for tr in ds.trajectories] == [f"lerobot_so101_ep{k}" for k in range(4)]
    assert ds.meta["excluded_joints"] == ["gripper"]
    src = ds.meta["source_logs"][0]
    assert src["units"] == {"robot_type": "so_follower", "arm_units": "range", "calibration": str(CALIBRATION)}
    assert src["fps"] == 50 and src["codebase_version"] == "v3.0"
    runs = read_runs(FIXTURE, SO101_JOINTS, None, LeRobotUnits(units.calibration, str(CALIBRATION), "range",
                                                                {"gripper": SO101_GRIPPER}))
    sage_map = LogMap.load(REPO / "data" / "so101" / "map.toml")
    for run, name in zip(runs, SAGE_RUNS):
        (sage,) = read_runs(REPO / "data" / "so101" / "logs" / name, SO101_JOINTS, sage_map)
        n = len(run.log["q"])
        assert n == 300
        np.testing.assert_allclose(run.log["q"], sage.log["q"][:n], rtol=0, atol=FLOAT32_RAD)
        held = np.searchsorted(sage.log["t_cmd"], sage.log["t"][:n], side="right") - 1
        np.testing.assert_allclose(run.log["q_cmd"], sage.log["q_cmd"][held], rtol=0, atol=FLOAT32_RAD)
        np.testing.assert_allclose(run.log["t"], np.arange(n) / 50, atol=1e-6)


def test_units_as_lerobot_defines_them(tmp_path):
    """Degrees: q = deg·(4095/4096)·π/180 (LeRobot divides by 4095 ticks, a turn has 4096); range units:
    q = v/100·(range_max − range_min)/2 ticks, negated with drive_mode 1; gripper 0..100 onto the joint range."""
    eps = [(np.array([[90.0, -45.0, 10.0, 0.0, 100.0, 0.0]] * 3, np.float32),
            np.array([[-100.0, 50.0, 0.0, 1.0, -2.0, 100.0]] * 3, np.float32))]
    _write_lerobot(tmp_path / "deg", "v3.0", eps, [f"{j}.pos" for j in SO101_JOINTS])
    ds = import_runs([tmp_path / "deg"], _robot(), RATE, lerobot=LeRobotUnits(arm="degrees"))
    rad = math.pi / 180 * 4095 / 4096
    np.testing.assert_allclose(ds.trajectories[0].q[0, :5], np.array([90, -45, 10, 0, 100]) * rad, rtol=1e-12)
    assert ds.trajectories[0].q[0, 5] == pytest.approx(SO101_GRIPPER[0])
    assert ds.trajectories[0].q_cmd[0, 5] == pytest.approx(SO101_GRIPPER[1])

    cal = {m: {"id": i + 1, "drive_mode": int(m == "elbow_flex"), "homing_offset": 0, "range_min": 1000,
               "range_max": 3048} for i, m in enumerate(SO101_JOINTS)}
    (tmp_path / "cal.json").write_text(json.dumps(cal))
    ds = import_runs([tmp_path / "deg"], _robot(), RATE, lerobot=LeRobotUnits.load(tmp_path / "cal.json"))
    half = 1024 * 2 * math.pi / 4096  # half of a 2048-tick range [rad]
    np.testing.assert_allclose(ds.trajectories[0].q[0, :5], np.array([0.9, -0.45, -0.1, 0.0, 1.0]) * half,
                               rtol=1e-6)


def test_missing_calibration_and_bad_input_fail_in_one_line(tmp_path, capsys):
    """No calibration for range units, a calibration without a motor, values outside LeRobot's range units, an
    unknown robot type given units, a map given with LeRobot's units, unknown motor names: one line each."""
    from wresdyn.cli import main

    out = tmp_path / "out"
    base = ["collect", "--robot", str(REPO / "scenes" / "so101" / "so101.xml"), "--no-gap", "--out", str(out)]
    assert main(base + ["--logs", str(FIXTURE), "--lerobot-units", "range"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(FIXTURE / "meta" / "info.json") in err and "--lerobot-calibration" in err, err
    assert not out.exists()

    robot = _robot()
    cal = json.loads(CALIBRATION.read_text())
    del cal["wrist_roll"]
    (tmp_path / "cal.json").write_text(json.dumps(cal))
    with pytest.raises(DatasetError, match="no motor 'wrist_roll'") as e:
        import_runs([FIXTURE], robot, RATE, lerobot=LeRobotUnits.load(tmp_path / "cal.json", "range"))
    assert "\n" not in str(e.value)
    for bad, match in (({"x": {"range_min": 5, "range_max": 5}}, "range_min 5 and range_max 5"),
                       ({"x": {"range_min": 1.5, "range_max": 9}}, "integer range_min"), ([], "maps motor names")):
        (tmp_path / "bad.json").write_text(json.dumps(bad))
        with pytest.raises(DatasetError, match=match):
            load_calibration(tmp_path / "bad.json")

    eps = [(np.full((4, 6), 120.0, np.float32), np.zeros((4, 6), np.float32))]
    _write_lerobot(tmp_path / "deg", "v2.1", eps, [f"{j}.pos" for j in SO101_JOINTS])
    with pytest.raises(DatasetError, match=r"row 0, observation.state\[0\] \(shoulder_pan\) = 120 lies outside "
                                           r"LeRobot's -100..100 range units.*--lerobot-units degrees"):
        import_runs([tmp_path / "deg"], robot, RATE, lerobot=LeRobotUnits.load(CALIBRATION))

    other = tmp_path / "koch"
    shutil.copytree(tmp_path / "deg", other)
    info = json.loads((other / "meta" / "info.json").read_text())
    info["robot_type"] = "koch_follower"
    (other / "meta" / "info.json").write_text(json.dumps(info))
    with pytest.raises(DatasetError, match="'koch_follower' is no LeRobot follower whose units are known"):
        import_runs([other], robot, RATE, lerobot=LeRobotUnits(arm="degrees"))

    (tmp_path / "map.toml").write_text('[units]\n"*" = "deg"\n')
    assert main(base + ["--logs", str(FIXTURE), "--map", str(tmp_path / "map.toml"), "--lerobot-calibration",
                        str(CALIBRATION)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "give it or LeRobot's calibration" in err, err

    names = [f"{j}.pos" for j in SO101_JOINTS]
    _write_lerobot(tmp_path / "pan", "v3.0", _episodes((5,)), ["pan.pos"] + names[1:])
    with pytest.raises(DatasetError, match=r"observation.state: joint\(s\) \['pan'\] are neither joints"):
        import_runs([tmp_path / "pan"], robot, RATE, lerobot=LeRobotUnits(arm="degrees"))
    assert not out.exists()


def test_cli_imports_the_fixture_without_a_map(tmp_path, capsys):
    """``wresdyn collect --logs LEROBOT_DIR --lerobot-units range --lerobot-calibration FILE``: joints by name, the
    gripper excluded, the units named on the terminal and in the dataset's meta."""
    from wresdyn.cli import main
    from wresdyn.robot.description import load_robot

    out = tmp_path / "out"
    so101 = REPO / "scenes" / "so101" / "so101.xml"
    assert main(["collect", "--robot", str(so101), "--logs", str(FIXTURE), "--lerobot-units", "range",
                 "--lerobot-calibration", str(CALIBRATION), "--assign", "*_ep0=train", "--assign", "*_ep1=validation",
                 "--no-gap", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "LeRobot so_follower, no map: joints by motor name, arm in range units" in text, text
    ds = load_dataset(out / "dataset.npz", load_robot(so101))
    assert ds.excluded_joints == ["gripper"] and [tr.split for tr in ds.trajectories] == ["train", "validation",
                                                                                           "train", "train"]
