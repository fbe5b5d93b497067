"""ROS 2 logs in MCAP files (rosbag2's default storage), read with the ``mcap`` and ``mcap-ros2-support`` packages.

One ``.mcap`` file is one run. The measured state is a ``sensor_msgs/msg/JointState`` topic (``position`` → q,
``velocity`` → q̇ and ``effort`` → τ where every message carries them), the command one of

* ``sensor_msgs/msg/JointState``: its ``position``, one command per message;
* ``trajectory_msgs/msg/JointTrajectory``: every point's ``positions`` at the message's stamp + ``time_from_start``;
  a message replaces the points of earlier ones from its own stamp on, as ROS's joint_trajectory_controller does;
* ``std_msgs/msg/Float64MultiArray`` (ros2_control's forward command controllers): its ``data``, one entry per joint
  in the order :attr:`McapTopics.command_joints` gives (default: the state topic's joint order).

Joints are mapped by name as in every other format (:func:`~wresdyn.data.log_files.map_joints`, with the mapping
file). Time stamps: a topic's header stamps where every message has a non-zero one, else the time the recorder logged
the message (MCAP ``log_time``); ``Float64MultiArray`` has no header and always uses log time. Both topics are
counted from the earliest stamp of the two, so nanosecond epoch stamps keep their precision as float64 seconds.
Messages are taken in log-time order; stamps that then do not increase are an error, as in every other format.
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .dataset import DatasetError
from .log_files import IDENTITY, LogMap, check_finite, check_stamps, map_joints

__all__ = ["McapTopics", "STATE_TYPE", "COMMAND_TYPES", "STAMPS", "is_mcap", "mcap_files", "read_mcap"]

STATE_TYPE = "sensor_msgs/msg/JointState"
"""ROS 2 type of the measured-state topic."""
COMMAND_TYPES = ("sensor_msgs/msg/JointState", "trajectory_msgs/msg/JointTrajectory", "std_msgs/msg/Float64MultiArray")
"""ROS 2 types a command topic may carry."""
STAMPS = ("auto", "header", "log")
"""Which time stamps are read: header stamps where every message has one (else log time), header only, log only."""
NS = 1e-9
MAGIC = b"\x89MCAP0\r\n"
"""The first bytes of every MCAP file."""
"""Seconds per nanosecond (ROS and MCAP stamps are integer nanoseconds)."""


@dataclass(frozen=True)
class McapTopics:
    """Which topics of an MCAP log hold the measured state and the commands, and which stamps are read."""

    state: str = "/joint_states"
    """Topic of the measured state (``sensor_msgs/msg/JointState``; joint_state_broadcaster's default)."""
    command: str | None = None
    """Topic of the commands; ``None``: the one topic besides ``state`` that carries a command type
    (:data:`COMMAND_TYPES`), an error when there are none or several."""
    command_joints: tuple[str, ...] = ()
    """``Float64MultiArray`` commands: the joint of each entry, in order (the controller's ``joints`` parameter);
    empty: the state topic's joint order."""
    stamps: str = "auto"
    """One of :data:`STAMPS`."""

    def __post_init__(self):
        if self.stamps not in STAMPS:
            raise DatasetError(f"MCAP stamps {self.stamps!r}: choose from {', '.join(STAMPS)}")


def _short(schema_name: str) -> str:
    """``pkg/msg/Type`` and ``pkg/Type`` are the same type."""
    return schema_name.replace("/msg/", "/")


def is_mcap(path) -> bool:
    """Whether ``path`` names an MCAP file (by its suffix)."""
    return Path(path).suffix.lower() == ".mcap"


def mcap_files(path) -> list[Path]:
    """The ``.mcap`` files directly in folder ``path``, in name order (none for a file)."""
    p = Path(path)
    return sorted(c for c in p.iterdir() if c.is_file() and is_mcap(c)) if p.is_dir() else []


def _scan(path: Path, topics: McapTopics) -> tuple[dict[str, str], str, dict[str, tuple]]:
    """Every topic's type, the command topic, and the raw messages of the state and command topics:
    ``{topic: (schema, channel, [(log_time [ns], data bytes)])}``. A file the ``mcap`` reader rejects is one line."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is not None and summary.channels:
                types = {c.topic: summary.schemas[c.schema_id].name if c.schema_id in summary.schemas else "(no schema)"
                         for c in summary.channels.values()}
            else:  # a file written without summary section (or without channels in it): one pass lists its topics
                types = {c.topic: s.name if s is not None else "(no schema)" for s, c, _ in reader.iter_messages()}
            if topics.state not in types:
                raise DatasetError(f"{path}: no topic {topics.state!r} (topics: {_listing(types)}); choose the "
                                   "JointState topic with --topic-state")
            command = topics.command or _command_topic(path, types, topics.state)
            if command not in types:
                raise DatasetError(f"{path}: no topic {command!r} (topics: {_listing(types)}); choose the command "
                                   "topic with --topic-command")
            raw: dict[str, tuple] = {}
            for schema, channel, message in reader.iter_messages(topics=[topics.state, command]):
                entry = raw.setdefault(channel.topic, (schema, channel, []))
                entry[2].append((message.log_time, message.data))
    except DatasetError:
        raise
    except Exception as e:  # the mcap reader raises many types on a truncated or corrupt file; report one line
        with open(path, "rb") as f:
            cut = f.read(len(MAGIC)) == MAGIC
        hint = ("; a file cut short (a recorder killed before closing it) is repaired by the mcap CLI's "
                "'mcap recover'") if cut else ""
        raise DatasetError(f"{path}: not a readable MCAP file ({type(e).__name__}: {_first_line(e)}){hint}") from None
    for topic in (topics.state, command):
        if topic not in raw:
            raise DatasetError(f"{path}: topic {topic!r} has no messages")
    return types, command, raw


def _first_line(e: Exception) -> str:
    s = str(e).strip()
    return s.splitlines()[0] if s else "no message"


def _listing(types: dict[str, str]) -> str:
    return ", ".join(f"{t} ({n})" for t, n in sorted(types.items())) or "none"


def _command_topic(path: Path, types: dict[str, str], state: str) -> str:
    candidates = sorted(t for t, n in types.items() if t != state and _short(n) in map(_short, COMMAND_TYPES))
    if len(candidates) != 1:
        which = f"several ({', '.join(candidates)})" if candidates else "none"
        raise DatasetError(f"{path}: --topic-command not given and {which} of the other topics carry a command type "
                           f"({', '.join(COMMAND_TYPES)}); topics: {_listing(types)}")
    return candidates[0]


def _decode(path: Path, topic: str, entry: tuple, allowed: tuple[str, ...]) -> tuple[str, list, np.ndarray]:
    """The type, decoded messages and log times [ns] (M,) of one topic; a type not in ``allowed`` or not ROS 2
    CDR is an error."""
    from mcap_ros2.decoder import DecoderFactory

    schema, channel, messages = entry
    name = schema.name if schema is not None else "(no schema)"
    if _short(name) not in map(_short, allowed):
        raise DatasetError(f"{path}: topic {topic!r} carries {name}, which is not supported here (expected "
                           f"{' or '.join(allowed)})")
    try:
        with contextlib.redirect_stderr(io.StringIO()):  # the vendored rosidl parser prints each bad line there
            decoder = DecoderFactory().decoder_for(channel.message_encoding, schema)
    except Exception as e:  # the stored message definition does not parse (empty, or a dependency missing)
        raise DatasetError(f"{path}: topic {topic!r}: the file's definition of {name} does not parse "
                           f"({type(e).__name__}: {_first_line(e)})") from None
    if decoder is None:
        raise DatasetError(f"{path}: topic {topic!r}: messages encoded {channel.message_encoding!r} with a "
                           f"{schema.encoding!r} schema; only ROS 2 CDR messages with ros2msg schemas are read")
    out = []
    for k, (_, data) in enumerate(messages):
        try:
            out.append(decoder(data))
        except Exception as e:  # a corrupt message body: CDR underrun, bad string, ...
            raise DatasetError(f"{path}: topic {topic!r}, message {k}: cannot decode a {name} "
                               f"({type(e).__name__}: {_first_line(e)})") from None
    return _short(name), out, np.array([t for t, _ in messages], dtype=np.int64)


def _stamps(path: Path, topic: str, msgs: list, log_ns: np.ndarray, how: str, has_header: bool) -> tuple:
    """Stamps [ns] (M,) of one topic's messages and which they are (``"header"`` or ``"log"``)."""
    if not has_header:
        if how == "header":
            raise DatasetError(f"{path}: topic {topic!r} has no header stamps (Float64MultiArray); use "
                               "--topic-stamps auto or log")
        return log_ns, "log"
    header = np.array([m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec for m in msgs], dtype=np.int64)
    zero = np.flatnonzero(header == 0)
    if how == "log" or (how == "auto" and len(zero)):
        return log_ns, "log"
    if len(zero):
        raise DatasetError(f"{path}: topic {topic!r}, message {int(zero[0])} has no header stamp (0); use "
                           "--topic-stamps auto or log")
    return header, "header"


def _rows(path: Path, topic: str, names_field: str, msgs: list, values: list[tuple[str, list]]
          ) -> tuple[list[str], dict[str, np.ndarray | None]]:
    """One row per message of named vectors: the joint names of the first message, and for each ``(key, rows)``
    of ``values`` an (M, n) array in that order (``None`` where every row is empty)."""
    names = list(getattr(msgs[0], names_field))
    if not names:
        raise DatasetError(f"{path}: topic {topic!r}, message 0: no joint names in {names_field}")
    if len(set(names)) != len(names):
        raise DatasetError(f"{path}: topic {topic!r}, message 0: duplicated joint names in {names_field} {names}")
    index = {n: j for j, n in enumerate(names)}
    orders = []
    for k, m in enumerate(msgs):
        got = list(getattr(m, names_field))
        if got != names:
            if sorted(got) != sorted(names):
                raise DatasetError(f"{path}: topic {topic!r}, message {k}: joints {got} differ from message 0's "
                                   f"{names}")
            orders.append([index[n] for n in got])
        else:
            orders.append(None)
    out: dict[str, np.ndarray | None] = {}
    for key, rows in values:
        lengths = {len(r) for r in rows}
        if lengths == {0} and key != "position":
            out[key] = None
            continue
        bad = next((k for k, r in enumerate(rows) if len(r) != len(names)), None)
        if bad is not None:
            raise DatasetError(f"{path}: topic {topic!r}, message {bad}: {key} has {len(rows[bad])} values for "
                               f"{len(names)} joints")
        a = np.empty((len(rows), len(names)))
        for k, (r, order) in enumerate(zip(rows, orders)):
            if order is None:
                a[k] = r
            else:
                a[k, order] = r
        out[key] = a
    return names, out


def _trajectory(path: Path, topic: str, msgs: list, base: np.ndarray) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Command stamps [ns] (M,), positions (M, n) and joint names (n,) of JointTrajectory messages: each point at its
    message's stamp + ``time_from_start``; a message drops the earlier messages' points from its own stamp on."""
    where = f"{path}: topic {topic!r}"
    check_stamps(where, (base - base[0]) * NS, np.arange(len(base)), "message")
    names = list(msgs[0].joint_names)
    if len(set(names)) != len(names):
        raise DatasetError(f"{where}, message 0: duplicated joint names in joint_names {names}")
    t: list[int] = []
    rows: list[np.ndarray] = []
    for k, (m, b) in enumerate(zip(msgs, base)):
        got = list(m.joint_names)
        if sorted(got) != sorted(names):
            raise DatasetError(f"{where}, message {k}: joints {got} differ from message 0's {names}")
        order = [got.index(n) for n in names]
        keep = int(np.searchsorted(np.array(t, dtype=np.int64), b, side="left"))
        del t[keep:], rows[keep:]
        prev = -1
        for i, p in enumerate(m.points):
            tfs = p.time_from_start.sec * 1_000_000_000 + p.time_from_start.nanosec
            if tfs < 0:
                raise DatasetError(f"{where}, message {k}: point {i}'s time_from_start ({tfs * NS:.6g} s) is negative")
            if tfs <= prev:
                raise DatasetError(f"{where}, message {k}: point {i}'s time_from_start ({tfs * NS:.6g} s) does not "
                                   "increase")
            prev = tfs
            if len(p.positions) != len(got):
                raise DatasetError(f"{where}, message {k}, point {i}: {len(p.positions)} positions for {len(got)} "
                                   "joints")
            t.append(int(b) + tfs)
            rows.append(np.asarray(p.positions, dtype=np.float64)[order])
    if not t:
        raise DatasetError(f"{where}: no trajectory point")
    return np.array(t, dtype=np.int64), np.stack(rows), names


def read_mcap(path, joint_names: list[str], log_map: LogMap | None = None, topics: McapTopics | None = None
              ) -> tuple[dict, dict]:
    """Read one MCAP file into :func:`~wresdyn.data.logs.read_log` arrays in ``joint_names`` order.

    Returns:
        ``(log, info)``: ``log`` has ``t`` (N,) [s], ``q`` (N, n) [rad], ``qd`` (N, n) [rad/s] or None, ``tau``
        (N, n) [N*m] or None at the state stamps, ``t_cmd`` (M,) [s] and ``q_cmd`` (M, n) [rad] at the command
        stamps, both counted from ``info["t0_ns"]``; ``info`` (for the dataset's meta) names the topics, their types
        and which stamps were read (``"header"`` or ``"log"``).
    """
    path, log_map, topics = Path(path), log_map or IDENTITY, topics or McapTopics()
    if not path.is_file():
        raise DatasetError(f"{path}: log file not found")
    types, command, raw = _scan(path, topics)
    _, states, state_log = _decode(path, topics.state, raw[topics.state], (STATE_TYPE,))
    t_state, state_stamps = _stamps(path, topics.state, states, state_log, topics.stamps, True)
    where = f"{path}: topic {topics.state!r}"
    check_stamps(where, (t_state - t_state[0]) * NS, np.arange(len(t_state)), "message")
    if len(states) < 2:
        raise DatasetError(f"{where}: needs at least two messages, has {len(states)}")
    names, st = _rows(path, topics.state, "name", states, [(k, [getattr(m, k) for m in states])
                                                              for k in ("position", "velocity", "effort")])
    kind, cmds, cmd_log = _decode(path, command, raw[command], COMMAND_TYPES)
    cwhere = f"{path}: topic {command!r}"
    if topics.command_joints and kind != "std_msgs/Float64MultiArray":
        raise DatasetError(f"{cwhere}: --topic-command-joints names the entries of Float64MultiArray commands; this "
                           f"topic carries {types[command]}, which names its joints itself")
    if kind == "std_msgs/Float64MultiArray":
        t_cmd, cmd_stamps = _stamps(path, command, cmds, cmd_log, topics.stamps, False)
        check_stamps(cwhere, (t_cmd - t_cmd[0]) * NS, np.arange(len(t_cmd)), "message")
        cnames = list(topics.command_joints) or names
        bad = next((k for k, m in enumerate(cmds) if len(m.data) != len(cnames)), None)
        if bad is not None:
            src = "--topic-command-joints" if topics.command_joints else f"the joints of {topics.state!r}"
            raise DatasetError(f"{cwhere}, message {bad}: {len(cmds[bad].data)} values, {src} name {len(cnames)} "
                               f"joints ({', '.join(cnames)}); give the controller's joint order with "
                               "--topic-command-joints")
        q_cmd = np.array([list(m.data) for m in cmds], dtype=np.float64).reshape(len(cmds), len(cnames))
    elif kind == "trajectory_msgs/JointTrajectory":
        base, cmd_stamps = _stamps(path, command, cmds, cmd_log, topics.stamps, True)
        t_cmd, q_cmd, cnames = _trajectory(path, command, cmds, base)
    else:
        t_cmd, cmd_stamps = _stamps(path, command, cmds, cmd_log, topics.stamps, True)
        check_stamps(cwhere, (t_cmd - t_cmd[0]) * NS, np.arange(len(t_cmd)), "message")
        cnames, c = _rows(path, command, "name", cmds, [("position", [m.position for m in cmds])])
        q_cmd = c["position"]
    for key in ("position", "velocity", "effort"):
        if st[key] is not None:
            check_finite(where, key, st[key], names, np.arange(len(states)), "message")
    check_finite(cwhere, "command", q_cmd, cnames, np.arange(len(q_cmd)), "command")
    t0 = int(min(t_state[0], t_cmd[0]))
    t, tc = (t_state - t0) * NS, (t_cmd - t0) * NS
    if not tc[0] < t[-1]:
        raise DatasetError(f"{cwhere}: the first command (t = {tc[0]:.6g} s) does not come before the last state "
                           f"(t = {t[-1]:.6g} s; stamps: state {state_stamps}, command {cmd_stamps}; other clocks? "
                           "try --topic-stamps log)")
    mapped = map_joints(names, {"q": st["position"], "qd": st["velocity"], "tau": st["effort"]}, joint_names, log_map,
                        where)
    cmd = map_joints(cnames, {"q_cmd": q_cmd}, joint_names, log_map, cwhere)
    log = {"t": t, "q": mapped["q"], "qd": None if log_map.velocity == "derived" else mapped["qd"],
           "q_cmd": cmd["q_cmd"], "tau": mapped["tau"], "t_cmd": tc}
    info = {"format": "mcap", "t0_ns": t0,
            "topics": {"state": {"topic": topics.state, "type": types[topics.state], "stamps": state_stamps,
                                 "messages": len(states)},
                       "command": {"topic": command, "type": types[command], "stamps": cmd_stamps,
                                   "messages": len(cmds)}}}
    return log, info
