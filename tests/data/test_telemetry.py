"""Telemetry checks on import (:mod:`wresdyn.data.telemetry`): a clean log of every format raises nothing; each
defect (jitter, gaps, clipped, frozen, constant commands, units) written into a log the importers read is found
through :func:`~wresdyn.data.importers.import_runs`; ``wresdyn collect --logs`` prints the warning lines and writes
``telemetry.json``; an unusable run is a one-line error, exit 2, nothing written."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from test_importers import SAGE_JOINTS, SO101_JOINTS, FakeRobot, _write_lerobot, _write_map, _write_sage

from wresdyn.data.dataset import DatasetError
from wresdyn.data.importers import import_runs
from wresdyn.data.telemetry import GAP_FACTOR, JITTER_WARN, STUCK_ERROR_RAD, STUCK_SECONDS

REPO = Path(__file__).resolve().parents[2]
SO101 = REPO / "scenes" / "so101" / "so101.xml"
RATE = 500.0
LOG_HZ = 50.0
"""The SO-101 logs' loop rate."""
TICK = 2 * math.pi / 4096
"""An STS3215's position resolution [rad]: the clean logs are quantised to it, as real servo readings are, so
exact repeats of a joint at rest are part of clean data."""
ARM = SO101_JOINTS[:5]


def _clean(n=500, seed=0, hz=LOG_HZ):
    """A clean 10 s run of the five SO-101 arm joints plus the gripper, robot order: stamps at ``hz`` with 1 %
    jitter from t = 7 s, multisine commands within ±0.6 rad, positions following them 60 ms late (a servo's lag),
    quantised to the servo's tick, velocities their exact derivative."""
    rng = np.random.default_rng(seed)
    t = 7.0 + np.arange(n) / hz + rng.uniform(-0.005, 0.005, n) / hz
    j = np.arange(6)[None]
    f = 0.2 + 0.07 * j

    def wave(tt):
        return 0.4 * np.sin(2 * np.pi * f * tt[:, None] + j) + 0.2 * np.sin(2 * np.pi * 3 * f * tt[:, None])

    q_cmd = wave(t)
    q = np.round(wave(t - 0.06) / TICK) * TICK
    qd = np.gradient(wave(t - 0.06), t, axis=0)
    q_cmd[:, 5], q[:, 5], qd[:, 5] = 0.5 + 0.5 * q_cmd[:, 5], 0.5 + 0.5 * q[:, 5], 0.5 * qd[:, 5]  # in its range
    return {"t": t, "q": q, "qd": qd, "q_cmd": q_cmd}


def _write_csv(path: Path, log: dict, names=SO101_JOINTS):
    cols = {"time": log["t"]}
    for i, n in enumerate(names):
        cols[f"q_{n}"], cols[f"q_cmd_{n}"] = log["q"][:, i], log["q_cmd"][:, i]
        if log.get("qd") is not None:
            cols[f"qd_{n}"] = log["qd"][:, i]
    lines = [",".join(cols)] + [",".join(repr(float(c[r])) for c in cols.values()) for r in range(len(log["t"]))]
    path.write_text("\n".join(lines) + "\n")
    return path


def _write(tmp_path: Path, fmt: str, log: dict, name="run") -> Path:
    """``log`` in robot order (SO101_JOINTS, radians) as a file or folder of format ``fmt``."""
    if fmt == "csv":
        return _write_csv(tmp_path / f"{name}.csv", log)
    if fmt == "npz":
        path = tmp_path / f"{name}.npz"
        np.savez(path, time=log["t"], joint_names=np.array(SO101_JOINTS), q=log["q"], q_cmd=log["q_cmd"],
                 qd=log["qd"])
        return path
    if fmt == "sage":  # commands on their own stamps, 7 ms after each state
        n = len(log["t"])
        _write_sage(tmp_path / name, log["t"], log["q"], log["qd"], np.zeros((n, 6)), log["t"] + 0.007,
                    log["q_cmd"], names=SO101_JOINTS)
        return tmp_path / name
    if fmt == "lerobot":  # degrees on LeRobot's own frame clock
        _write_lerobot(tmp_path / name, "v3.0", [(np.degrees(log["q"]), np.degrees(log["q_cmd"]))], SO101_JOINTS,
                       fps=int(LOG_HZ))
        return tmp_path / name
    raise ValueError(fmt)


DEG_MAP = '[units]\n"*" = "deg"\n'


def _findings(tmp_path: Path, paths, log_map=None, exclude=()) -> list[dict]:
    """The telemetry findings of importing ``paths`` onto the SO-101's joints (limits ±pi, gripper its range)."""
    text = (log_map or "") + (f"[exclude]\njoints = {list(exclude)!r}\n" if exclude else "")
    m = _write_map(tmp_path / "map.toml", text) if text else None
    ds = import_runs([Path(p) for p in paths], FakeRobot(SO101_JOINTS), RATE, log_map=m)
    return ds.meta["telemetry"]


def _checks(findings) -> list[tuple[str, str]]:
    return sorted((f["check"], f["joint"]) for f in findings)


@pytest.mark.parametrize("fmt", ["csv", "npz", "sage", "lerobot"])
def test_clean_logs_raise_nothing(tmp_path, fmt):
    """Jitter of 1 %, a servo's lag and its quantisation are clean data in every format."""
    path = _write(tmp_path, fmt, _clean())
    assert _findings(tmp_path, [path], DEG_MAP if fmt == "lerobot" else None) == []


def test_jitter_and_gaps(tmp_path):
    log = _clean(seed=1)
    rng = np.random.default_rng(2)
    jittery = dict(log, t=7.0 + (np.arange(500) + rng.uniform(-0.35, 0.35, 500)) / LOG_HZ)  # std 20 % of a period
    (f,) = _findings(tmp_path, [_write(tmp_path, "csv", jittery, "jittery")])
    assert f["check"] == "jitter" and f["joint"] == "" and f["numbers"]["jitter"] > JITTER_WARN
    assert f["message"].startswith("jittery: sampling jitter ") and "\n" not in f["message"]

    keep = np.r_[0:200, 210:300, 303:500]  # 10 samples dropped at 4 s, 3 more at 6 s
    gappy = {k: v[keep] for k, v in log.items()}
    (f,) = _findings(tmp_path, [_write(tmp_path, "sage", gappy, "gappy")])
    assert f["check"] == "gaps" and f["run"] == "gappy"
    assert f["numbers"]["gaps"] == 2 and f["numbers"]["dropped_samples"] == 13
    assert f["numbers"]["longest_gap_s"] == pytest.approx(11 / LOG_HZ, rel=0.02)
    assert f["numbers"]["at_s"] == pytest.approx(199 / LOG_HZ, abs=0.01)
    # one late sample (1.5 periods) is jitter's business, not a gap
    late = dict(log, t=log["t"] + np.where(np.arange(500) == 250, 0.5 / LOG_HZ, 0.0))
    assert (1.5 < GAP_FACTOR) and _findings(tmp_path, [_write(tmp_path, "csv", late, "late")]) == []


def test_gaps_over_half_the_run_are_an_error(tmp_path):
    log = _clean()
    keep = np.r_[0:100, 400:500]  # 6 s of 10 missing
    path = _write(tmp_path, "csv", {k: v[keep] for k, v in log.items()}, "holes")
    with pytest.raises(DatasetError, match=r"holes\.csv: gaps cover 6\d % of the run .* fix or drop this run"):
        _findings(tmp_path, [path])


def test_clipped_and_frozen_joints(tmp_path):
    """Clipped: the elbow reads its run maximum while commanded beyond it; frozen: the wrist repeats one reading in
    the middle of its range while its command moves away; the same in a SAGE run and a LeRobot dataset."""
    log = _clean(seed=3)
    q = log["q"].copy()
    top = 0.05
    q[:, 2] = np.minimum(q[:, 2], top)  # its command peaks at 0.46 rad: more than 0.2 rad beyond for over 0.5 s
    q[250:330, 3] = q[250, 3]  # 1.6 s of one reading
    bad = dict(log, q=q)
    for fmt in ("sage", "lerobot"):
        (tmp_path / fmt).mkdir()
        found = _findings(tmp_path / fmt, [_write(tmp_path / fmt, fmt, bad)], DEG_MAP if fmt == "lerobot" else None)
        assert _checks(found) == [("clipped", "elbow_flex"), ("frozen", "wrist_flex")], (fmt, found)
        clipped, frozen = sorted(found, key=lambda f: f["check"])
        assert clipped["numbers"]["value_rad"] == pytest.approx(top, abs=1e-5)
        assert clipped["numbers"]["command_rad"] > top + STUCK_ERROR_RAD
        assert clipped["numbers"]["longest_s"] >= STUCK_SECONDS
        assert frozen["numbers"]["stretches"] == 1 and frozen["numbers"]["longest_s"] <= 1.6 + 0.05
        assert "wrist_flex frozen: " in frozen["message"] and "stale reading" in frozen["message"]
    # a joint at rest on its command repeats its reading too: not stuck
    rest = dict(log, q=log["q"].copy(), q_cmd=log["q_cmd"].copy())
    rest["q_cmd"][100:300, 1] = rest["q"][100:300, 1] = 0.3
    assert _findings(tmp_path, [_write(tmp_path, "csv", rest, "rest")]) == []


def test_every_fitted_joint_frozen_is_an_error_unless_excluded(tmp_path):
    log = _clean()
    frozen = dict(log, q=np.broadcast_to(log["q"][:1], log["q"].shape).copy())
    frozen["q"][:, 5] = log["q"][:, 5]  # the gripper still moves: not a fitted joint
    path = _write(tmp_path, "csv", frozen, "dead")
    with pytest.raises(DatasetError, match=r"dead\.csv: every fitted joint's measured position is constant"):
        _findings(tmp_path, [path], exclude=("gripper",))


def test_constant_commands(tmp_path):
    """A joint held in one run is one line for the run; held in every run, one more for the dataset; excluded
    joints are not judged."""
    logs = []
    for k, idle in enumerate([(0, 4), (4,)]):
        log = _clean(seed=k)
        log["q_cmd"][:, idle] = 0.1
        logs.append(_write(tmp_path, "csv", log, f"r{k}"))
    found = _findings(tmp_path, logs)
    assert _checks(found) == [("command_constant", "shoulder_pan,wrist_roll"), ("command_constant", "wrist_roll"),
                              ("never_excited", "wrist_roll")]
    first = next(f for f in found if f["run"] == "r0")
    assert first["numbers"]["joints"] == ["shoulder_pan", "wrist_roll"] and first["numbers"]["command_rad"] == [0.1] * 2
    assert first["message"].startswith("r0: command constant over the whole run (10.0 s) on shoulder_pan +0.100, "
                                       "wrist_roll +0.100 rad: ")
    log = _clean()
    log["q_cmd"][:, 5] = 0.4
    assert _findings(tmp_path, [_write(tmp_path, "csv", log, "grip")], exclude=("gripper",)) == []


def test_units(tmp_path):
    """Degrees read as radians: a LeRobot dataset (degrees) mapped as radians, and degrees per second in a CSV's
    velocity columns; a wrong offset is called that, not degrees."""
    log = _clean(seed=4)
    found = _findings(tmp_path, [_write(tmp_path, "lerobot", log)], '[units]\n"*" = "rad"\n')
    assert {f["check"] for f in found} == {"units"} and sorted(f["joint"] for f in found) == sorted(SO101_JOINTS)
    pan = next(f for f in found if f["joint"] == "shoulder_pan")
    assert pan["numbers"]["degrees"] and "looks like degrees read as radians" in pan["message"]
    assert pan["numbers"]["max_rad"] > math.pi

    deg_s = dict(log, qd=np.degrees(log["qd"]))
    found = _findings(tmp_path, [_write(tmp_path, "csv", deg_s, "vel")])
    assert _checks(found) == [("velocity_units", j) for j in sorted(SO101_JOINTS)]
    assert all(f["numbers"]["ratio"] == pytest.approx(180 / math.pi, rel=0.15) for f in found)
    assert "(degrees per second?)" in found[0]["message"]

    shift = np.array([0, 0, 0, 4.0, 0, 0])  # a zero 4 rad off: 1.5 rad beyond pi, its spread still fits the range
    offset = dict(log, q=log["q"] + shift, q_cmd=log["q_cmd"] + shift)
    (f,) = _findings(tmp_path, [_write(tmp_path, "csv", offset, "offset")])
    assert (f["check"], f["joint"]) == ("units", "wrist_flex") and not f["numbers"]["degrees"]
    assert "wrong zero offset, scale or units" in f["message"]


@pytest.fixture(scope="module")
def so101_file():
    if not SO101.is_file():
        pytest.skip(f"{SO101} not there yet")
    return SO101


def test_the_simulated_real_so101_is_clean(tmp_path, so101_file, record):
    """A multisine recorded on the project's simulated real SO-101 (MuJoCo, its mismatch config, sensor noise),
    written as an NPZ log and imported onto the robot file's own limits: no finding."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.robot.description import load_robot

    robot = load_robot(so101_file)
    (tr,) = record(robot, Mismatch.load(so101_file.parent / "mismatch.toml"), {"train": 1}, 3.0,
                   amplitude=0.4).trajectories
    path = tmp_path / "sim.npz"
    np.savez(path, time=tr.t, joint_names=np.array(robot.joint_names), q=tr.q, q_cmd=tr.q_cmd, qd=tr.qd)
    assert import_runs([path], robot, RATE).meta["telemetry"] == []


def test_cli_writes_warnings_and_report_or_fails_writing_nothing(tmp_path, so101_file, capsys):
    """collect --logs on a SAGE run with a frozen wrist: the warning line on stdout and in collect.log, the record
    in telemetry.json and the dataset's meta; a run with gaps over most of it: exit 2, one line, no folder."""
    from wresdyn.cli import main
    from wresdyn.data.dataset import load_dataset

    log = _clean(seed=5)
    log["q"][250:330, 3] = log["q"][250, 3]
    _write_sage(tmp_path / "logs" / "wave", log["t"], log["q"], log["qd"], np.zeros((500, 6)), log["t"] + 0.007,
                log["q_cmd"], names=SAGE_JOINTS)
    m = tmp_path / "map.toml"
    m.write_text("[joints]\n" + "".join(f'{a} = "{b}"\n' for a, b in zip(SAGE_JOINTS, SO101_JOINTS))
                 + '[exclude]\njoints = ["gripper"]\n')
    out = tmp_path / "out"
    assert main(["collect", "--robot", str(so101_file), "--logs", str(tmp_path / "logs"), "--map", str(m),
                 "--out", str(out), "--no-gap"]) == 0
    text = capsys.readouterr().out
    lines = [ln for ln in text.splitlines() if ln.startswith("warning: ")]
    assert len(lines) == 1 and lines[0].startswith("warning: wave: wrist_flex frozen: "), text
    assert "telemetry checks (docs/logs.md): 1 warning(s):" in text
    assert lines[0] in (out / "collect.log").read_text().splitlines()
    (record,) = json.loads((out / "telemetry.json").read_text())
    assert {k: record[k] for k in ("run", "joint", "check")} == {"run": "wave", "joint": "wrist_flex",
                                                                 "check": "frozen"}
    assert lines[0] == "warning: " + record["message"] and record["numbers"]["longest_s"] > STUCK_SECONDS
    assert load_dataset(out / "dataset.npz").meta["telemetry"] == [record]

    keep = np.r_[0:100, 450:500]
    _write_sage(tmp_path / "logs" / "holes", log["t"][keep], log["q"][keep], log["qd"][keep], np.zeros((150, 6)),
                log["t"][keep] + 0.007, log["q_cmd"][keep], names=SAGE_JOINTS)
    bad = tmp_path / "bad"
    assert main(["collect", "--robot", str(so101_file), "--logs", str(tmp_path / "logs"), "--map", str(m),
                 "--out", str(bad), "--no-gap"]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and str(tmp_path / "logs" / "holes") in err and "gaps cover" in err, err
    assert not bad.exists()
