"""MCAP / ROS 2 logs: bags written by mcap-ros2-support's own writer, imported and checked against what was written."""

from pathlib import Path

import numpy as np
import pytest

from wresdyn.data.dataset import DatasetError, load_dataset
from wresdyn.data.importers import import_runs, read_runs
from wresdyn.data.logs import import_log
from wresdyn.data.mcap_logs import McapTopics, read_mcap

pytest.importorskip("mcap_ros2")  # a dependency of the package; its absence is an install error, reported here

REPO = Path(__file__).resolve().parents[2]
SO101 = REPO / "scenes" / "so101" / "so101.xml"
RATE = 500.0
T0_NS = 1_764_400_000_123_456_789
"""An epoch stamp [ns] (late 2025): float64 seconds since 1970 would lose the sub-microsecond part."""
STATE_HZ, CMD_HZ = 200.0, 50.0

_RULE = "=" * 80
_HEADER = f"""{_RULE}
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
{_RULE}
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
JOINT_STATE = f"""std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
{_HEADER}"""
JOINT_TRAJECTORY = f"""std_msgs/Header header
string[] joint_names
JointTrajectoryPoint[] points
{_HEADER}{_RULE}
MSG: trajectory_msgs/JointTrajectoryPoint
float64[] positions
float64[] velocities
float64[] accelerations
float64[] effort
builtin_interfaces/Duration time_from_start
{_RULE}
MSG: builtin_interfaces/Duration
int32 sec
uint32 nanosec
"""
FLOAT64_MULTI_ARRAY = f"""std_msgs/MultiArrayLayout layout
float64[] data
{_RULE}
MSG: std_msgs/MultiArrayLayout
MultiArrayDimension[] dim
uint32 data_offset
{_RULE}
MSG: std_msgs/MultiArrayDimension
string label
uint32 size
uint32 stride
"""
DEFS = {"sensor_msgs/msg/JointState": JOINT_STATE, "trajectory_msgs/msg/JointTrajectory": JOINT_TRAJECTORY,
        "std_msgs/msg/Float64MultiArray": FLOAT64_MULTI_ARRAY}


@pytest.fixture(scope="module")
def so101():
    from wresdyn.robot.description import load_robot

    return load_robot(SO101)


def _stamp(ns: int) -> dict:
    return {"sec": int(ns // 1_000_000_000), "nanosec": int(ns % 1_000_000_000)}


def _signals(n: int, seconds: float = 1.0, state_hz: float = STATE_HZ, cmd_hz: float = CMD_HZ):
    """Known content: states at ``state_hz`` (q_j = 0.3 sin(2π 0.7 t + j), its derivative, a torque), commands at
    ``cmd_hz`` that change every message, starting 5 ms after the first state (another loop)."""
    t = np.arange(int(seconds * state_hz) + 1) / state_hz
    j = np.arange(n)[None]
    w = 2 * np.pi * 0.7
    q = 0.3 * np.sin(w * t[:, None] + j)
    qd = 0.3 * w * np.cos(w * t[:, None] + j)
    tau = 0.5 * np.cos(t[:, None] + j)
    t_cmd = 0.005 + np.arange(int(seconds * cmd_hz)) / cmd_hz
    q_cmd = 0.2 * np.sin(3.0 * t_cmd[:, None] + j) + 0.01 * np.arange(len(t_cmd))[:, None]
    return t, q, qd, tau, t_cmd, q_cmd


def _write(path, names, sig, command="sensor_msgs/msg/JointState", state_topic="/joint_states",
           cmd_topic="/joint_commands", header_stamps=True, cmd_names=None, extra=None, state_log_t=None,
           header_clock_ns=T0_NS):
    """An MCAP file as rosbag2 writes it: ``names`` the state's joint order (the commands' unless ``cmd_names``);
    log time = stamp + 1 ms of transport (states: ``state_log_t`` + 1 ms where given); header stamps count from
    ``header_clock_ns`` (another clock than the recorder's where it differs from ``T0_NS``); ``extra(writer,
    schemas)`` adds messages of its own."""
    from mcap_ros2.writer import Writer

    t, q, qd, tau, t_cmd, q_cmd = sig
    cmd_names = names if cmd_names is None else cmd_names
    perm = [names.index(n) for n in cmd_names]
    with open(path, "wb") as f:
        w = Writer(f)
        schemas = {k: w.register_msgdef(k, v) for k, v in DEFS.items()}
        msgs = []
        for k in range(len(t)):
            ns = T0_NS + round(t[k] * 1e9)
            stamp = ns - T0_NS + header_clock_ns if header_stamps else 0
            msg = {"header": {"stamp": _stamp(stamp), "frame_id": ""}, "name": names,
                   "position": q[k].tolist(), "velocity": qd[k].tolist(), "effort": tau[k].tolist()}
            log_ns = ns if state_log_t is None else T0_NS + round(state_log_t[k] * 1e9)
            msgs.append((log_ns, state_topic, schemas["sensor_msgs/msg/JointState"], msg))
        for k in range(len(t_cmd)):
            ns = T0_NS + round(t_cmd[k] * 1e9)
            header = {"stamp": _stamp(ns - T0_NS + header_clock_ns if header_stamps else 0), "frame_id": ""}
            values = q_cmd[k][perm].tolist()
            if command == "sensor_msgs/msg/JointState":
                msg = {"header": header, "name": cmd_names, "position": values, "velocity": [], "effort": []}
            elif command == "trajectory_msgs/msg/JointTrajectory":
                msg = {"header": header, "joint_names": cmd_names,
                       "points": [{"positions": values, "time_from_start": {"sec": 0, "nanosec": 0}}]}
            else:
                msg = {"layout": {"dim": [], "data_offset": 0}, "data": values}
            msgs.append((ns, cmd_topic, schemas[command], msg))
        for ns, topic, schema, msg in sorted(msgs, key=lambda m: m[0]):
            w.write_message(topic, schema, msg, log_time=ns + 1_000_000)
        if extra:
            extra(w, schemas)
        w.finish()
    return path


@pytest.mark.parametrize("command", list(DEFS))
def test_each_command_type_imports_to_the_written_values(tmp_path, so101, command):
    """States at 200 Hz in a scrambled joint order, commands at 50 Hz on their own stamps: measured values
    are interpolated onto the 500 Hz grid, commands held, from header stamps (Float64MultiArray: log time,
    which the writer puts 1 ms after the stamp)."""
    names = list(so101.joint_names)
    scrambled = names[::-1]
    sig = _signals(len(names))
    t, q, qd, tau, t_cmd, q_cmd = sig
    perm = [names.index(n) for n in scrambled]
    scr = (t, q[:, perm], qd[:, perm], tau[:, perm], t_cmd, q_cmd[:, perm])
    path = _write(tmp_path / "arm.mcap", scrambled, scr, command=command)
    log, info = read_mcap(path, names)
    header = command != "std_msgs/msg/Float64MultiArray"
    assert info["topics"]["state"]["stamps"] == "header" and info["topics"]["command"]["topic"] == "/joint_commands"
    assert info["topics"]["command"]["stamps"] == ("header" if header else "log")
    assert info["t0_ns"] == T0_NS
    np.testing.assert_allclose(log["t"], t, atol=1e-9)  # counted from the first stamp: nanosecond exact
    np.testing.assert_allclose(log["t_cmd"], t_cmd + (0 if header else 1e-3), atol=1e-9)
    np.testing.assert_array_equal(log["q"], q)  # back in the robot's joint order
    np.testing.assert_array_equal(log["qd"], qd)
    np.testing.assert_array_equal(log["tau"], tau)
    # Float64MultiArray entries follow the state topic's joint order by default
    np.testing.assert_array_equal(log["q_cmd"], q_cmd)

    ds = import_runs([path], so101, RATE)
    tr = ds.trajectories[0]
    assert tr.name == "arm" and ds.meta["source_logs"][0]["format"] == "mcap"
    shift = t_cmd[0] + (0 if header else 1e-3)  # the grid starts at the first state stamp at which a command holds
    grid = tr.t + shift
    np.testing.assert_allclose(tr.q, np.stack([np.interp(grid, t, q[:, j]) for j in range(len(names))], 1),
                               atol=1e-12)
    held = np.searchsorted(t_cmd + shift - t_cmd[0], grid + 1e-9, side="right") - 1
    np.testing.assert_array_equal(tr.q_cmd, q_cmd[held])
    assert len(tr.t) == int((t[-1] - shift) * RATE + 1e-6) + 1
    one = import_log(path, so101, RATE)  # the one-log library call reads the same
    assert one.name == "arm"
    np.testing.assert_array_equal(one.q_cmd, tr.q_cmd)


def test_folder_of_bags_via_cli(tmp_path, so101, capsys):
    """A folder of two bags is two runs; log-time stamps where the headers are empty; a JointTrajectory with two
    points per message, the second replaced by the next message; the topics reported."""
    from wresdyn.cli import main

    names = list(so101.joint_names)
    logs = tmp_path / "bags"
    logs.mkdir()
    _write(logs / "b_second.mcap", names, _signals(len(names), seconds=0.6), header_stamps=False)

    def trajectory(w, schemas):  # commands: at 2.0 s and 2.3 s, then at 2.1 s (replacing the 2.3 s point)
        s = schemas["trajectory_msgs/msg/JointTrajectory"]
        for base, pts in ((2_000_000_000, [(0, 0.1), (300_000_000, 0.9)]), (2_100_000_000, [(0, 0.2)])):
            msg = {"header": {"stamp": _stamp(T0_NS + base), "frame_id": ""}, "joint_names": names,
                   "points": [{"positions": [v] * len(names), "time_from_start": {"sec": 0, "nanosec": d}}
                              for d, v in pts]}
            w.write_message("/arm/joint_trajectory", s, msg, log_time=T0_NS + base)

    sig = _signals(len(names), seconds=2.5)
    _write(logs / "a_first.mcap", names, sig, cmd_topic="/joint_commands", extra=trajectory)
    out = tmp_path / "o"
    args = ["collect", "--robot", str(SO101), "--logs", str(logs), "--topic-command", "/arm/joint_trajectory",
            "--no-gap", "--out", str(out)]
    assert main(args) == 2  # the second bag has no such topic
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "b_second.mcap: no topic '/arm/joint_trajectory'" in err, err
    assert "/joint_commands (sensor_msgs/msg/JointState)" in err and not out.exists()

    (logs / "b_second.mcap").rename(tmp_path / "b_second.mcap")
    assert main(args) == 0
    text = capsys.readouterr().out
    assert "command /arm/joint_trajectory (trajectory_msgs/msg/JointTrajectory, 2 messages, header stamps)" in text
    ds = load_dataset(out / "dataset.npz", so101)
    tr = ds.trajectories[0]
    assert tr.name == "a_first" and tr.split == "heldout" and abs(tr.t[-1] - 0.5) < 1e-9
    k = np.round(tr.t * RATE).astype(int)
    np.testing.assert_array_equal(tr.q_cmd[:, 0], np.where(k < 50, 0.1, 0.2))  # 0.9 at 2.3 s never holds

    assert main(["collect", "--robot", str(SO101), "--logs", str(logs), str(tmp_path / "b_second.mcap"), "--no-gap",
                 "--topic-command", "/joint_commands", "--topic-stamps", "log", "--out", str(tmp_path / "two")]) == 0
    text = capsys.readouterr().out
    assert text.count(" mcap ") == 2 and "command /joint_commands (sensor_msgs/msg/JointState, 30 messages, log" in text
    ds = load_dataset(tmp_path / "two" / "dataset.npz", so101)
    assert [tr.name for tr in ds.trajectories] == ["a_first", "b_second"]


def _copy(src, dst, extra=None, **options):
    """``src``'s messages rewritten by the plain MCAP writer with ``options``; ``extra(writer)`` adds records."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f, open(dst, "wb") as g:
        w = Writer(g, **options)
        w.start(profile="ros2", library="test")
        schemas, channels = {}, {}
        for schema, channel, m in make_reader(f).iter_messages(log_time_order=False):
            if schema.id not in schemas:
                schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
            if channel.id not in channels:
                channels[channel.id] = w.register_channel(channel.topic, channel.message_encoding, schemas[schema.id])
            w.add_message(channels[channel.id], m.log_time, m.data, m.publish_time)
        if extra:
            extra(w)
        w.finish()
    return dst


def _expect(path, so101, match, topics=None):
    with pytest.raises(DatasetError, match=match) as e:
        read_runs(path, list(so101.joint_names), topics=topics)
    assert str(path) in str(e.value) and "\n" not in str(e.value), str(e.value)


def test_errors_are_one_line(tmp_path, so101):
    names = list(so101.joint_names)
    sig = _signals(len(names), seconds=0.3)
    p = _write(tmp_path / "ok.mcap", names, sig)
    _expect(p, so101, r"no topic '/states' \(topics: /joint_commands \(sensor_msgs/msg/JointState\), /joint_states "
            r"\(sensor_msgs/msg/JointState\)\)", McapTopics(state="/states"))
    _expect(p, so101, "no topic '/cmd'", McapTopics(command="/cmd"))
    _expect(p, so101, "names the entries of Float64MultiArray commands; this topic carries sensor_msgs/msg/JointState",
            McapTopics(command_joints=tuple(names)))
    p = _write(tmp_path / "array.mcap", names, sig, command="std_msgs/msg/Float64MultiArray")
    _expect(p, so101, r"message 0: 6 values, --topic-command-joints name 3 joints \(a, b, c\)",
            McapTopics(command_joints=("a", "b", "c")))
    _expect(p, so101, r"joint\(s\) \['jaw'\] are neither", McapTopics(command_joints=tuple(names[:5]) + ("jaw",)))

    def twist(w, schemas):
        s = w.register_msgdef("geometry_msgs/msg/Vector3", "float64 x\nfloat64 y\nfloat64 z\n")
        w.write_message("/cmd_vel", s, {"x": 1.0, "y": 0.0, "z": 0.0}, log_time=T0_NS)
        empty = {"header": {"stamp": _stamp(T0_NS), "frame_id": ""}, "joint_names": names, "points": []}
        w.write_message("/joint_trajectory", schemas["trajectory_msgs/msg/JointTrajectory"], empty, log_time=T0_NS)
    p = _write(tmp_path / "twist.mcap", names, sig, extra=twist)
    _expect(p, so101, r"several \(/joint_commands, /joint_trajectory\)")
    _expect(p, so101, "topic '/cmd_vel' carries geometry_msgs/msg/Vector3, which is not supported",
            McapTopics(command="/cmd_vel"))

    # a file without chunks, indexes or channels in its summary (a streaming recorder's): read in one pass
    from mcap.writer import IndexType

    p = _copy(tmp_path / "ok.mcap", tmp_path / "stream.mcap", use_chunking=False, index_types=IndexType.NONE,
              repeat_channels=False, repeat_schemas=False, use_statistics=False, use_summary_offsets=False)
    log, info = read_mcap(p, names)
    np.testing.assert_array_equal(log["q_cmd"], read_mcap(tmp_path / "ok.mcap", names)[0]["q_cmd"])

    p = _write(tmp_path / "arm.mcap", names[:5] + ["jaw"], sig)
    _expect(p, so101, r"topic '/joint_states': joint\(s\) \['jaw'\] are neither joints of the robot")

    t, *rest = sig
    t_bad = t.copy()
    t_bad[7] = t_bad[5]  # an earlier header stamp (log time still increases)
    p = _write(tmp_path / "late.mcap", names, (t_bad, *rest), state_log_t=t)
    _expect(p, so101, r"topic '/joint_states': decreasing time stamp at message 7")

    p = _write(tmp_path / "unstamped.mcap", names, sig, header_stamps=False)
    assert read_mcap(p, names)[1]["topics"]["state"]["stamps"] == "log"  # auto: log time where headers are 0
    _expect(p, so101, r"topic '/joint_states', message 0 has no header stamp \(0\)", McapTopics(stamps="header"))
    # states stamped on a simulated clock (100 s), commands without header (the recorder's epoch log time)
    p = _write(tmp_path / "clocks.mcap", names, sig, command="std_msgs/msg/Float64MultiArray",
               header_clock_ns=100_000_000_000)
    _expect(p, so101, r"the first command \(t = 1\.76\d+e\+09 s\) does not come before the last state \(t = 0\.3 s; "
            r"stamps: state header, command log; other clocks\? try --topic-stamps log\)")
    assert read_mcap(p, names, topics=McapTopics(stamps="log"))[1]["topics"]["state"]["stamps"] == "log"

    def broken(definition: bytes, data: bytes):
        def extra(w):
            sid = w.register_schema("std_msgs/msg/Float64MultiArray", "ros2msg", definition)
            w.add_message(w.register_channel("/cmd", "cdr", sid), T0_NS, data, T0_NS)
        return extra
    p = _copy(tmp_path / "ok.mcap", tmp_path / "nodef.mcap", broken(b"float64[ data", b""))
    _expect(p, so101, r"topic '/cmd': the file's definition of std_msgs/msg/Float64MultiArray does not parse "
            r"\(InvalidResourceName", McapTopics(command="/cmd"))
    p = _copy(tmp_path / "ok.mcap", tmp_path / "body.mcap", broken(FLOAT64_MULTI_ARRAY.encode(), b"\0\1"))
    _expect(p, so101, r"topic '/cmd', message 0: cannot decode a std_msgs/msg/Float64MultiArray",
            McapTopics(command="/cmd"))

    good = (tmp_path / "ok.mcap").read_bytes()
    (tmp_path / "junk.mcap").write_bytes(b"not an mcap file at all")
    _expect(tmp_path / "junk.mcap", so101, r"not a readable MCAP file \(InvalidMagic")
    (tmp_path / "cut.mcap").write_bytes(good[: len(good) // 2])
    _expect(tmp_path / "cut.mcap", so101, "not a readable MCAP file .*'mcap recover'")
    _expect(tmp_path / "absent.mcap", so101, "log file not found")
