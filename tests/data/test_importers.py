"""Real-log importers: SAGE runs, LeRobot datasets (v2.x and v3.0), the mapping file, multi-run datasets with
split assignment, the shipped SO-101 subset, and one-line errors for bad input (nothing written)."""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from wresdyn.data.dataset import DatasetError, load_dataset
from wresdyn.data.importers import SplitRule, import_runs, load_split_map, parse_assign, read_runs, read_sage
from wresdyn.data.lerobot import LeRobotUnits
from wresdyn.data.logs import LogMap, import_log, resample

REPO = Path(__file__).resolve().parents[2]
SO101 = REPO / "scenes" / "so101" / "so101.xml"
SHIPPED = REPO / "data" / "so101"
SO101_JOINTS = ["shoulder_pan", "shoulder_lift", "elbow_flex", "wrist_flex", "wrist_roll", "gripper"]
SAGE_JOINTS = ["Rotation", "Pitch", "Elbow", "Wrist_Pitch", "Wrist_Roll", "Jaw"]
RATE = 500.0
SO101_GRIPPER = (-0.17453297762778586, 1.7453291995659765)
"""The gripper's range in scenes/so101/so101.xml [rad]."""


@dataclass
class FakeRobot:
    """The fields :func:`import_runs` reads of a :class:`~wresdyn.robot.description.Robot`, without loading one."""

    joint_names: list
    source: Path = Path("robot.xml")
    source_sha256: str = "0" * 64

    def gains_record(self):
        return None

    @property
    def lower(self):
        """Joint lower limits [rad]: the SO-101 file's gripper range for a joint named gripper, else -pi."""
        return np.array([SO101_GRIPPER[0] if j == "gripper" else -math.pi for j in self.joint_names])

    @property
    def upper(self):
        return np.array([SO101_GRIPPER[1] if j == "gripper" else math.pi for j in self.joint_names])


def _write_map(path: Path, text: str) -> LogMap:
    path.write_text(text)
    return LogMap.load(path)


SO101_MAP = """
[joints]
Rotation = "shoulder_pan"
Pitch = "shoulder_lift"
Elbow = "elbow_flex"
Wrist_Pitch = "wrist_flex"
Wrist_Roll = "wrist_roll"
Jaw = "gripper"
[units]
"*" = "rad"
Pitch = "deg"
Jaw = { scale = 2.0, offset = -0.5 }
[exclude]
joints = ["Jaw"]
"""


def _vec(row) -> str:
    return "[" + ", ".join(repr(float(x)) for x in row) + "]"


def _write_sage(run: Path, t_state_s, q, qd, tau, t_cmd_s, q_cmd, names=SAGE_JOINTS, events=None):
    """A SAGE run folder as SAGE writes it: stamps in microseconds, vectors as quoted "[a, b, ...]" fields."""
    run.mkdir(parents=True, exist_ok=True)
    (run / "joint_list.txt").write_text("\n".join(names) + "\n")
    lines = ["type,timestamp,positions"] + [f'CONTROL,{float(t) * 1e6!r},"{_vec(c)}"' for t, c in zip(t_cmd_s, q_cmd)]
    (run / "control.csv").write_text("\r\n".join(lines) + "\r\n")
    lines = ["type,timestamp,positions,velocities,torques"]
    lines += [f'STATE_MOTOR,{float(t) * 1e6!r},"{_vec(a)}","{_vec(b)}","{_vec(c)}"'
              for t, a, b, c in zip(t_state_s, q, qd, tau)]
    (run / "state_motor.csv").write_text("\r\n".join(lines) + "\r\n")
    if events is not None:
        ev = ["type,timestamp,event", "EVENT,0,CONTROL_MODE_ENABLE"]
        ev += [f"EVENT,{float(t) * 1e6!r},{n}" for n, t in events]
        (run / "event.csv").write_text("\n".join(ev) + "\n")


def _sage_signals(n_state=60, n_joints=6, seed=0):
    """Known content: states at ~50 Hz with jitter from t = 3 s (clock origin arbitrary), commands on their own
    stamps 7 ms after each state, a command that changes every sample."""
    rng = np.random.default_rng(seed)
    t = 3.0 + np.arange(n_state) * 0.02 + rng.uniform(-0.001, 0.001, n_state)
    j = np.arange(n_joints)[None]
    q = 0.2 * np.sin(2 * np.pi * 0.8 * t[:, None] + j)
    qd = 0.2 * 2 * np.pi * 0.8 * np.cos(2 * np.pi * 0.8 * t[:, None] + j)
    tau = 0.1 * np.cos(t[:, None] + j)
    t_cmd = t + 0.007
    q_cmd = 0.01 * np.arange(n_state)[:, None] + 0.1 * j
    return t, q, qd, tau, t_cmd, q_cmd


def test_sage_run_joins_commands_and_states_on_their_own_stamps(tmp_path):
    t, q, qd, tau, t_cmd, q_cmd = _sage_signals()
    run = tmp_path / "wave"
    # MOTION_START at the 4th state: the three before are dropped, the command in force then is kept
    _write_sage(run, t, q, qd, tau, t_cmd, q_cmd, events=[("MOTION_START", t[3]), ("DISABLE", t[-1] + 1.0)])
    m = _write_map(tmp_path / "map.toml", SO101_MAP)
    log = read_sage(run, SO101_JOINTS, m)
    scale = np.array([1, math.pi / 180, 1, 1, 1, 2.0])
    offset = np.array([0, 0, 0, 0, 0, -0.5])
    np.testing.assert_allclose(log["t"], t[3:], rtol=0, atol=1e-9)  # microseconds -> seconds
    np.testing.assert_allclose(log["t_cmd"], t_cmd, rtol=0, atol=1e-9)
    np.testing.assert_allclose(log["q"], q[3:] * scale + offset, atol=1e-12)  # degrees and the jaw's scale/offset
    np.testing.assert_allclose(log["qd"], qd[3:] * scale, atol=1e-12)  # velocities: scale only
    np.testing.assert_allclose(log["q_cmd"], q_cmd * scale + offset, atol=1e-12)
    np.testing.assert_array_equal(log["tau"], tau[3:])  # torques as logged
    for same in (run / "control.csv", run / "state_motor.csv"):  # a run's file names its run
        np.testing.assert_array_equal(read_sage(same, SO101_JOINTS, m)["q"], log["q"])

    r = resample(log, RATE)
    # the grid starts at the first kept state (a command, logged 7 ms after the previous state, is in force)
    t_abs = t[3] + r["t"]
    held = np.searchsorted(t_cmd, t_abs + 1e-9, side="right") - 1
    np.testing.assert_array_equal(r["q_cmd"], log["q_cmd"][held])  # zero-order hold on the command stamps
    assert held[0] == 2 and (np.diff(held) >= 0).all()
    k = 37  # an inner grid point: states interpolated linearly between their own stamps
    i = np.searchsorted(t, t_abs[k]) - 1
    w = (t_abs[k] - t[i]) / (t[i + 1] - t[i])
    np.testing.assert_allclose(r["q"][k], ((1 - w) * q[i] + w * q[i + 1]) * scale + offset, atol=1e-9)

    ds = import_runs([run], FakeRobot(SO101_JOINTS), RATE, m)
    (tr,) = ds.trajectories
    assert tr.name == "wave" and tr.split == "heldout" and ds.meta["excluded_joints"] == ["gripper"]
    src = ds.meta["source_logs"][0]
    assert src["format"] == "sage" and src["samples"] == len(t) - 3
    assert src["median_rate_hz"] == pytest.approx(50.0, rel=0.01) and 0 < src["jitter"] < 0.1
    assert src["trimmed_s"][0] == pytest.approx(t[3] - t[0], abs=1e-9)
    np.testing.assert_array_equal(tr.q_cmd, r["q_cmd"])


def _write_lerobot(root: Path, version: str, episodes, names, fps=30):
    """A LeRobot dataset: v2.x one parquet file per episode, v3.0 all episodes in one file (fixed-size lists);
    v2.0 lists the names as ``{"motors": [...]}``."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    n = len(names)
    feat = {"dtype": "float32", "shape": [n], "names": {"motors": names} if version == "v2.0" else names}
    info = {"codebase_version": version, "fps": fps, "robot_type": "so101_follower",
            "features": {"action": feat, "observation.state": feat,
                         "timestamp": {"dtype": "float32", "shape": [1], "names": None},
                         "episode_index": {"dtype": "int64", "shape": [1], "names": None}}}
    (root / "meta").mkdir(parents=True)
    (root / "meta" / "info.json").write_text(json.dumps(info))
    (root / "data" / "chunk-000").mkdir(parents=True)
    list_type = pa.list_(pa.float32()) if version.startswith("v2") else pa.list_(pa.float32(), n)

    def table(eps):
        cols = {"observation.state": [], "action": [], "timestamp": [], "frame_index": [], "episode_index": []}
        for k, (state, action) in eps:
            cols["observation.state"] += state.tolist()
            cols["action"] += action.tolist()
            cols["timestamp"] += list(np.arange(len(state)) / fps)
            cols["frame_index"] += list(range(len(state)))
            cols["episode_index"] += [k] * len(state)
        return pa.table({"observation.state": pa.array(cols["observation.state"], list_type),
                         "action": pa.array(cols["action"], list_type),
                         "timestamp": pa.array(cols["timestamp"], pa.float32()),
                         "frame_index": pa.array(cols["frame_index"], pa.int64()),
                         "episode_index": pa.array(cols["episode_index"], pa.int64())})

    if version.startswith("v2"):
        for k, ep in enumerate(episodes):
            pq.write_table(table([(k, ep)]), root / "data" / "chunk-000" / f"episode_{k:06d}.parquet")
    else:
        pq.write_table(table(list(enumerate(episodes))), root / "data" / "chunk-000" / "file-000.parquet")


def _episodes(lengths=(40, 25), n=6, seed=1):
    rng = np.random.default_rng(seed)
    return [(rng.uniform(-90, 90, (k, n)).astype(np.float32), rng.uniform(-90, 90, (k, n)).astype(np.float32))
            for k in lengths]


LEROBOT_MAP = """
[units]
"*" = "deg"
gripper = { scale = 0.01 }   # 0..100 -> 0..1 rad
[exclude]
joints = ["gripper"]
"""


@pytest.mark.parametrize("version", ["v2.1", "v3.0"])
def test_lerobot_dataset_one_trajectory_per_episode(tmp_path, version):
    names = [f"{j}.pos" for j in SO101_JOINTS]
    eps = _episodes()
    root = tmp_path / "so101_pick"
    _write_lerobot(root, version, eps, names)
    m = _write_map(tmp_path / "map.toml", LEROBOT_MAP)
    runs = read_runs(root, SO101_JOINTS, m)
    assert [r.name for r in runs] == ["so101_pick_ep0", "so101_pick_ep1"]
    scale = np.array([math.pi / 180] * 5 + [0.01])
    for r, (state, action) in zip(runs, eps):
        np.testing.assert_allclose(r.log["q"], state.astype(np.float64) * scale, rtol=1e-12)
        np.testing.assert_allclose(r.log["q_cmd"], action.astype(np.float64) * scale, rtol=1e-12)
        np.testing.assert_allclose(r.log["t"], np.arange(len(state)) / 30, atol=1e-6)
        assert r.log["qd"] is None and r.log["tau"] is None and r.info["codebase_version"] == version
    ds = import_runs([root], FakeRobot(SO101_JOINTS), RATE, m, SplitRule(patterns=(("*_ep1", "ood"),)))
    assert [(tr.name, tr.split) for tr in ds.trajectories] == [("so101_pick_ep0", "heldout"), ("so101_pick_ep1", "ood")]
    # the grid ends at or within one step before the last stamp (float32 stamps: 1.3 s is logged as 1.29999995)
    assert 39 / 30 - 1 / RATE <= ds.trajectories[0].t[-1] <= 39 / 30
    assert ds.meta["source_logs"][1]["median_rate_hz"] == pytest.approx(30.0, rel=1e-4)
    assert ds.meta["excluded_joints"] == ["gripper"]


def test_lerobot_v2_and_v3_give_the_same_dataset(tmp_path):
    eps = _episodes((12, 18))
    for v in ("v2.0", "v3.0"):
        _write_lerobot(tmp_path / v / "ds", v, eps, [f"{j}.pos" for j in SO101_JOINTS])
    a, b = (import_runs([tmp_path / v / "ds"], FakeRobot(SO101_JOINTS), RATE, lerobot=LeRobotUnits(arm="degrees"))
            for v in ("v2.0", "v3.0"))
    for x, y in zip(a.trajectories, b.trajectories):
        assert x.name == y.name
        np.testing.assert_array_equal(x.q, y.q)
        np.testing.assert_array_equal(x.q_cmd, y.q_cmd)


def test_split_rule():
    names = [f"run{i:02d}" for i in range(20)] + ["pick_a", "pick_b"]
    rule = SplitRule("train", (("pick_a", "ood"), ("pick_*", "heldout")), validation_fraction=0.2)
    s = rule.assign(names)
    assert s[-2:] == ["ood", "heldout"]  # first matching pattern wins
    assert s.count("validation") == 4 and s.count("train") == 16  # 20 % of the 20 unmatched, whole runs
    # deterministic and independent of the order runs are given in
    shuffled = names[::-1]
    assert dict(zip(shuffled, rule.assign(shuffled))) == dict(zip(names, s))
    assert SplitRule("train", validation_fraction=0.01).assign(names[:3]).count("validation") == 1  # at least one
    assert rule.unused(names) == [] and SplitRule(patterns=(("nope*", "ood"),)).unused(names) == ["nope*"]
    assert parse_assign("a=b*=ood") == ("a=b*", "ood")
    for bad in ("pick", "pick=test", "=ood"):
        with pytest.raises(DatasetError, match="PATTERN=SPLIT"):
            parse_assign(bad)
    with pytest.raises(DatasetError, match="sum to at most 1"):
        SplitRule(validation_fraction=0.6, heldout_fraction=0.5)
    with pytest.raises(DatasetError, match="ask for 1 \\+ 1 runs out of 1"):
        SplitRule(validation_fraction=0.5, heldout_fraction=0.5).assign(["x"])


def _one_line(e, *parts):
    msg = str(e.value)
    assert "\n" not in msg, msg
    for p in parts:
        assert str(p) in msg, msg


def test_map_and_split_map_files(tmp_path):
    m = _write_map(tmp_path / "m.toml", SO101_MAP)
    assert m.unit("Pitch", "shoulder_lift") == (math.pi / 180, 0.0) and m.unit("Elbow", "elbow_flex") == (1.0, 0.0)
    assert m.excluded_joints(SO101_JOINTS) == ["gripper"]
    p = tmp_path / "bad.toml"
    cases = {
        "[joint]\nA = 'b'\n": r"unknown key\(s\) \['joint'\]",
        "[units]\nA = 'grad'\n": r"\[units\] A = 'grad': unknown unit",
        "[units]\nA = { scale = 0 }\n": "non-zero number",
        "[joints]\nA = 'x'\nB = 'x'\n": r"several log joints onto \['x'\]",
        "[exclude]\njoints = 'gripper'\n": r"\[exclude\] joints must be a list",
        "velocity = 'guessed'\n": "velocity must be",
        "[joints\n": "not a readable TOML",
    }
    for text, match in cases.items():
        p.write_text(text)
        with pytest.raises(DatasetError, match=match) as e:
            LogMap.load(p)
        _one_line(e, p)
    m = _write_map(p, "[joints]\nRotation = 'shoulder_pan_joint'\n")
    with pytest.raises(DatasetError, match="'shoulder_pan_joint' is not a joint of robot.xml") as e:
        import_runs([tmp_path], FakeRobot(SO101_JOINTS), RATE, m)
    _one_line(e, p, "[joints] Rotation")
    p.write_text('"multi*" = "train"\n"pick" = "test"\n')
    with pytest.raises(DatasetError, match="the split must be one of") as e:
        load_split_map(p)
    _one_line(e, p, "'pick'")
    p.write_text('"multi*" = "train"\n"*" = "ood"\n')
    assert load_split_map(p) == [("multi*", "train"), ("*", "ood")]


def _good_sage(run: Path, **kw):
    t, q, qd, tau, t_cmd, q_cmd = _sage_signals(n_state=20)
    _write_sage(run, t, q, qd, tau, t_cmd, q_cmd, **kw)
    return run


def _edit(path: Path, row: int, old: str, new: str):
    """Replace ``old`` by ``new`` in data row ``row`` (1-based, after the header) of a CSV file."""
    lines = path.read_text().splitlines()
    assert old in lines[row], (old, lines[row])
    lines[row] = lines[row].replace(old, new, 1)
    path.write_text("\n".join(lines) + "\n")


def test_bad_sage_runs_fail_in_one_line_naming_file_row_and_column(tmp_path):
    robot = FakeRobot(SO101_JOINTS)
    m = _write_map(tmp_path / "map.toml", SO101_MAP)

    def expect(run, file, match, *parts):
        with pytest.raises(DatasetError, match=match) as e:
            import_runs([run], robot, RATE, m)
        _one_line(e, run / file if file else run, *parts)

    run = _good_sage(tmp_path / "r1")
    sm = run / "state_motor.csv"
    line = sm.read_text().splitlines()[5]
    first = line.split('"[')[1].split(",")[0]
    _edit(sm, 5, "[" + first, "[nan")
    expect(run, "state_motor.csv", r"positions has NaN/inf at data row 5 \(column 'positions'\[0\] \(Rotation\)")

    run = _good_sage(tmp_path / "r2")
    _edit(run / "state_motor.csv", 3, "[" + run.joinpath("state_motor.csv").read_text().splitlines()[3]
          .split('"[')[2].split(",")[0], "[x1")
    expect(run, "state_motor.csv", r"data row 3, column 'velocities'\[0\] \(Rotation\): '\[?x1' is not a number")

    run = _good_sage(tmp_path / "r3")
    lines = (run / "control.csv").read_text().splitlines()
    stamp = lines[6].split(",")[1]
    _edit(run / "control.csv", 7, lines[7].split(",")[1], stamp)
    expect(run, "control.csv", "duplicated time stamp at data row 7")
    _edit(run / "control.csv", 7, stamp, "1.0")
    expect(run, "control.csv", "decreasing time stamp at data row 7")

    run = _good_sage(tmp_path / "r4")
    _edit(run / "control.csv", 2, "]", ", 0.5]")
    expect(run, "control.csv", "data row 2, column 'positions' has 7 values, joint_list.txt names 6 joints")

    run = _good_sage(tmp_path / "r5")
    (run / "state_motor.csv").write_text((run / "state_motor.csv").read_text().replace("positions,", "pos,", 1))
    expect(run, "state_motor.csv", "no 'positions' column")

    run = _good_sage(tmp_path / "r6", names=SAGE_JOINTS[:5] + ["Claw"])
    expect(run, "joint_list.txt", r"joint\(s\) \['Claw'\] are neither joints of the robot nor mapped in")

    run = _good_sage(tmp_path / "r7")
    (run / "joint_list.txt").unlink()
    expect(run, None, "SAGE run has no joint_list.txt")

    # a raw SAGE file given as a plain CSV log: the column that is not a number is named, with a hint
    raw = tmp_path / "multisine_control.csv"
    shutil.copy(tmp_path / "r1" / "control.csv", raw)
    with pytest.raises(DatasetError, match=r"data row 1, column 1 \('type'\): 'CONTROL' is not a number \(a SAGE") as e:
        import_runs([raw], robot, RATE, m)
    _one_line(e, raw)


def test_bad_lerobot_datasets_fail_in_one_line(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    robot = FakeRobot(SO101_JOINTS)
    names = [f"{j}.pos" for j in SO101_JOINTS]

    def make(name, version="v3.0"):
        root = tmp_path / name
        _write_lerobot(root, version, _episodes((10, 10)), names)
        return root, sorted((root / "data").rglob("*.parquet"))[0]

    def expect(root, file, match):
        with pytest.raises(DatasetError, match=match) as e:
            import_runs([root], robot, RATE, lerobot=LeRobotUnits(arm="degrees"))
        _one_line(e, file)

    root, f = make("nan")
    t = pq.read_table(f)
    state = np.array(t.column("observation.state").to_pylist())
    state[13, 2] = np.nan
    t = t.set_column(t.schema.get_field_index("observation.state"), "observation.state",
                     pa.array(state.tolist(), pa.list_(pa.float32(), 6)))
    pq.write_table(t, f)
    expect(root, f, r"observation.state has NaN/inf at row 13 \(column 'observation.state'\[2\] \(elbow_flex\)")

    root, f = make("stamps", "v2.1")
    t = pq.read_table(f)
    ts = t.column("timestamp").to_numpy().copy()
    ts[4] = ts[2]
    pq.write_table(t.set_column(t.schema.get_field_index("timestamp"), "timestamp", pa.array(ts)), f)
    expect(root, f, "episode 0: decreasing time stamp at row 4")

    root, f = make("noaction")
    pq.write_table(pq.read_table(f).drop(["action"]), f)
    expect(root, f, "no column 'action'")

    root, _ = make("unknown")
    info = json.loads((root / "meta" / "info.json").read_text())
    info["features"]["action"]["names"] = ["pan.pos"] + names[1:]
    (root / "meta" / "info.json").write_text(json.dumps(info))
    expect(root, root / "meta" / "info.json", r"action: joint\(s\) \['pan'\] are neither joints of the robot nor")


def test_cli_reports_and_writes_nothing_on_error(tmp_path, humanoid, capsys):
    """End to end on the humanoid: SAGE runs with the robot's own joint names, two folders and a CSV, splits by
    pattern; then a bad run among good ones: one line on stderr, exit 2, no output folder."""
    from wresdyn.cli import main

    names = list(humanoid.joint_names)
    logs = tmp_path / "logs"
    for i, fam in enumerate(["multisine", "step", "pick_place"]):
        t, q, qd, tau, t_cmd, q_cmd = _sage_signals(n_state=15, n_joints=len(names), seed=i)
        _write_sage(logs / fam, t, q, qd, tau, t_cmd, 0.1 * np.sin(q_cmd), names=names)
    out = tmp_path / "o"
    args = ["collect", "--logs", str(logs), "--assign", "pick*=ood", "--assign", "step=validation", "--assign",
            "nothing*=heldout", "--out", str(out)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "note: split pattern 'nothing*' matches no run" in text
    assert text.count(" sage ") == 3 and "jitter" in text and "max gap" in text, text
    assert "PD-only vs real on validation" in text and "PD-only vs real on ood" in text
    ds = load_dataset(out / "dataset.npz", humanoid)
    assert {tr.name: tr.split for tr in ds.trajectories} == {"multisine": "train", "step": "validation",
                                                              "pick_place": "ood"}
    assert set(ds.meta["pd_only_gap"]) == {"validation", "ood"} and ds.meta["excluded_joints"] == []

    _edit(logs / "step" / "state_motor.csv", 9, "STATE_MOTOR,", "STATE_MOTOR,nan")
    bad_out = tmp_path / "bad"
    assert main(["collect", "--logs", str(logs), "--out", str(bad_out), "--no-gap"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(logs / "step" / "state_motor.csv") in err and "data row 9" in err, err
    assert not bad_out.exists()
    assert main(["collect", "--logs", str(logs / "multisine"), "--assign", "x=test", "--out", str(bad_out)]) == 2
    assert "PATTERN=SPLIT" in capsys.readouterr().err and not bad_out.exists()


@pytest.fixture(scope="module")
def so101():
    if not SO101.is_file():
        pytest.skip(f"{SO101} not there yet")
    from wresdyn.robot.description import load_robot

    return load_robot(SO101)


def test_shipped_so101_subset(tmp_path, so101, capsys):
    """The shipped SAGE subset, its map and split map, through the CLI; plus the PD-only gap on 2 s of it."""
    from wresdyn.cli import main

    out = tmp_path / "so101"
    assert main(["collect", "--robot", str(SO101), "--logs", str(SHIPPED / "logs"), "--map", str(SHIPPED / "map.toml"),
                 "--split-map", str(SHIPPED / "splits.toml"), "--out", str(out), "--no-gap"]) == 0
    ds = load_dataset(out / "dataset.npz", so101)
    splits = {tr.name: tr.split for tr in ds.trajectories}
    assert splits == {"figure_eight": "ood", "multisine": "train", "pick_place": "ood", "prbs_excitation": "validation",
                      "step_response": "heldout"}
    assert ds.meta["excluded_joints"] == ["gripper"]
    for tr, src in zip(ds.trajectories, ds.meta["source_logs"]):
        assert src["samples"] == 1000 and src["median_rate_hz"] == pytest.approx(49.85, abs=0.05)
        assert src["jitter"] < 0.01 and src["max_gap_s"] < 0.025
        assert tr.t[-1] == pytest.approx(20.0, abs=0.1) and tr.tau is not None
        assert (tr.q >= so101.lower - 0.05).all() and (tr.q <= so101.upper + 0.05).all()  # radians, right joints
        np.testing.assert_allclose(tr.q[0], tr.q_cmd[0], atol=0.15)  # starts near its first command
    assert "excluded from fitting (recorded values kept): gripper" in capsys.readouterr().out

    # 2 s of one run, with the PD-only replay of the nominal SO-101
    short = tmp_path / "short" / "step_response"
    short.mkdir(parents=True)
    for f in ("joint_list.txt", "event.csv"):
        shutil.copy(SHIPPED / "logs" / "step_response" / f, short / f)
    for f in ("control.csv", "state_motor.csv"):
        lines = (SHIPPED / "logs" / "step_response" / f).read_text().splitlines()[:101]
        (short / f).write_text("\n".join(lines) + "\n")
    tr = import_log(short, so101, RATE, log_map=LogMap.load(SHIPPED / "map.toml"))
    assert tr.name == "step_response" and tr.n_samples == int(tr.t[-1] * RATE) + 1
    assert main(["collect", "--robot", str(SO101), "--logs", str(short), "--map", str(SHIPPED / "map.toml"),
                 "--out", str(tmp_path / "gap")]) == 0
    gap = load_dataset(tmp_path / "gap" / "dataset.npz").meta["pd_only_gap"]["heldout"]
    assert 0 < gap["mean"] < 0.2 and gap["diverged"] == 0 and gap["excluded_joints"] == ["gripper"]
    # the gap averages over the five fitted joints only
    fitted = [gap["per_joint"][j] for j in SO101_JOINTS if j != "gripper"]
    assert gap["per_trajectory"]["step_response"] == pytest.approx(gap["mean"])
    assert gap["mean"] == pytest.approx(sum(fitted) / 5)
    assert "over the 5 fitted joints (excluded: gripper " in capsys.readouterr().out


def test_shipped_subset_is_small_and_attributed():
    files = [p for p in SHIPPED.rglob("*") if p.is_file()]
    assert sum(p.stat().st_size for p in files) < 2.0e6
    licence = (SHIPPED / "LICENSE-SAGE").read_text()
    assert licence.lstrip().startswith("Apache License") and "Version 2.0" in licence
    readme = (SHIPPED / "README.md").read_text()
    assert "isaac-sim2real/sage" in readme and "Apache-2.0" in readme
    runs = read_runs(SHIPPED / "logs", SO101_JOINTS, LogMap.load(SHIPPED / "map.toml"))
    assert len({r.name for r in runs}) == 5


def test_logs_without_gap_need_no_gains(tmp_path, capsys):
    """Importing with --no-gap replays nothing, so a robot without PD gains is fine; the gap replay refuses it."""
    from wresdyn.cli import main
    from wresdyn.robot.description import load_robot

    names = list(load_robot("newton:quadruped.urdf").joint_names)  # the file carries no gains
    t, q, qd, tau, t_cmd, q_cmd = _sage_signals(n_state=10, n_joints=len(names))
    _write_sage(tmp_path / "logs" / "run", t, q, qd, tau, t_cmd, 0.1 * np.sin(q_cmd), names=names)
    base = ["collect", "--robot", "newton:quadruped.urdf", "--logs", str(tmp_path / "logs")]
    assert main([*base, "--no-gap", "--out", str(tmp_path / "o")]) == 0
    assert load_dataset(tmp_path / "o" / "dataset.npz").gains is None
    assert main([*base, "--out", str(tmp_path / "gap")]) == 2
    assert "no PD gains" in capsys.readouterr().err and not (tmp_path / "gap").exists()
