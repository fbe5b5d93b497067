"""Real-log import: CSV and NPZ, joints by name, resampling onto the simulation step, errors."""

import numpy as np
import pytest

from wresdyn.data.dataset import DatasetError, load_dataset
from wresdyn.data.logs import import_log, import_logs

SIM_RATE = 500.0


def _signals(names, t):
    """Known log content: q_j = 0.3 sin(2π 0.7 t + j), its exact derivative, a command that changes every
    log sample, and a torque."""
    j = np.arange(len(names))[None]
    w = 2 * np.pi * 0.7
    q = 0.3 * np.sin(w * t[:, None] + j)
    qd = 0.3 * w * np.cos(w * t[:, None] + j)
    q_cmd = 0.01 * np.arange(len(t))[:, None] + j
    tau = 2.0 * np.cos(t[:, None] + j)
    return q, qd, q_cmd, tau


def _write_csv(path, names, t, q, qd, q_cmd, tau=None, bare=(), drop=(), extra=None):
    """Columns in a scrambled order: q_cmd first, then positions (bare joint name for joints in ``bare``)."""
    cols = {"time": t}
    for i, n in enumerate(names):
        cols[f"q_cmd_{n}"] = q_cmd[:, i]
    for i, n in reversed(list(enumerate(names))):
        cols[n if n in bare else f"q_{n}"] = q[:, i]
        if qd is not None:
            cols[f"qd_{n}"] = qd[:, i]
        if tau is not None:
            cols[f"tau_{n}"] = tau[:, i]
    for c in drop:
        cols.pop(c)
    if extra:
        cols.update(extra)
    keys = list(cols)
    lines = ["# a comment line, ignored", ",".join(keys)]
    lines += [",".join(repr(float(cols[k][r])) for k in keys) for r in range(len(t))]
    path.write_text("\n".join(lines) + "\n")


def test_csv_at_100hz_imports_and_resamples(tmp_path, humanoid):
    names = list(humanoid.joint_names)
    t_log = 12.5 + np.arange(101) / 100.0  # 1 s at 100 Hz, starting at an arbitrary clock time
    q, qd, q_cmd, tau = _signals(names, t_log)
    path = tmp_path / "walk.csv"
    _write_csv(path, names, t_log, q, qd, q_cmd, tau, bare=names[:3])
    tr = import_log(path, humanoid, SIM_RATE, split="ood")
    assert tr.name == "walk" and tr.split == "ood"
    np.testing.assert_array_equal(tr.t, np.arange(501) / SIM_RATE)  # starts at 0, ends at the last log sample
    assert tr.q.shape == tr.qd.shape == tr.qdd.shape == tr.q_cmd.shape == tr.tau.shape == (501, humanoid.n_dof)
    # every 5th simulation sample is a log sample: measured values there are the log's
    np.testing.assert_allclose(tr.q[::5], q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr.qd[::5], qd, rtol=0, atol=1e-12)
    # in between: linear interpolation (sample 7 is 2/5 of the way from log sample 1 to 2)
    np.testing.assert_allclose(tr.q[7], 0.6 * q[1] + 0.4 * q[2], atol=1e-12)
    np.testing.assert_allclose(tr.tau[7], 0.6 * tau[1] + 0.4 * tau[2], atol=1e-12)
    # commands are held: sample k carries the command logged at or before t_k, never interpolated
    np.testing.assert_array_equal(tr.q_cmd, q_cmd[np.arange(501) // 5])
    # q̈ derived from the resampled q̇: close to the analytic -0.3 ω² sin (linear interpolation error dominates)
    w = 2 * np.pi * 0.7
    expect = -0.3 * w * w * np.sin(w * (tr.t + 12.5)[:, None] + np.arange(humanoid.n_dof)[None])
    assert np.abs(tr.qdd - expect)[10:-10].max() < 0.05 * 0.3 * w * w


def test_jittered_log_without_velocity(tmp_path, humanoid):
    """Irregular time stamps (a 100 Hz clock with +-2 ms jitter) and no qd columns: q̇ is differentiated
    from q on the log's own stamps; commands are still held from the last logged sample."""
    names = list(humanoid.joint_names)
    rng = np.random.default_rng(0)
    t_log = np.arange(150) / 100.0 + rng.uniform(-0.002, 0.002, 150)
    t_log[0] = 0.0
    q, qd, q_cmd, _ = _signals(names, t_log)
    path = tmp_path / "jitter.csv"
    _write_csv(path, names, t_log, q, None, q_cmd)
    tr = import_log(path, humanoid, SIM_RATE)
    held = np.searchsorted(t_log, tr.t, side="right") - 1
    np.testing.assert_array_equal(tr.q_cmd, q_cmd[held])
    w = 2 * np.pi * 0.7
    expect = 0.3 * w * np.cos(w * tr.t[:, None] + np.arange(humanoid.n_dof)[None])
    assert np.abs(tr.qd - expect)[5:-5].max() < 0.02 * 0.3 * w
    assert tr.tau is None


def test_npz_log_maps_joints_by_name(tmp_path, humanoid):
    names = list(humanoid.joint_names)
    t_log = np.arange(60) / 250.0
    q, qd, q_cmd, tau = _signals(names, t_log)
    rev = names[::-1]
    np.savez(tmp_path / "a.npz", time=t_log, joint_names=np.array(rev), q=q[:, ::-1], qd=qd[:, ::-1],
             q_cmd=q_cmd[:, ::-1])
    np.savez(tmp_path / "b.npz", time=t_log, joint_names=np.array(names), q=q, q_cmd=q_cmd, tau=tau)
    ds = import_logs([tmp_path / "a.npz", tmp_path / "b.npz"], humanoid, SIM_RATE, split="train")
    a, b = ds.trajectories
    np.testing.assert_allclose(a.q[::2], q, atol=1e-12)
    np.testing.assert_array_equal(a.q_cmd, b.q_cmd)
    assert ds.mismatch == {} and ds.seed is None and ds.meta["source_logs"][0]["median_rate_hz"] == pytest.approx(250.0)
    ds.save(tmp_path / "real.npz")
    back = load_dataset(tmp_path / "real.npz", humanoid)
    np.testing.assert_array_equal(back.trajectories[1].tau, b.tau)


def _expect(path, match, humanoid):
    with pytest.raises(DatasetError, match=match) as e:
        import_log(path, humanoid)
    assert str(path) in str(e.value) and "\n" not in str(e.value)


def test_csv_errors(tmp_path, humanoid):
    names = list(humanoid.joint_names)
    t_log = np.arange(20) / 100.0
    q, qd, q_cmd, _ = _signals(names, t_log)
    p = tmp_path / "bad.csv"
    _write_csv(p, names, t_log, q, qd, q_cmd, drop=[f"q_{names[4]}"])
    _expect(p, rf"missing q_<joint> \(or <joint>\) column\(s\) for joint\(s\) \['{names[4]}'\]", humanoid)
    _write_csv(p, names, t_log, q, qd, q_cmd, drop=[f"q_cmd_{names[0]}"])
    _expect(p, "missing q_cmd_<joint>", humanoid)
    _write_csv(p, names, t_log, q, qd, q_cmd, drop=[f"qd_{names[2]}"])  # some velocities but not all
    _expect(p, "missing qd_<joint>", humanoid)
    _write_csv(p, names, t_log, q, qd, q_cmd, extra={"q_tail_joint": t_log})
    _expect(p, r"\['q_tail_joint'\] name no joint", humanoid)
    _write_csv(p, names, t_log, q, qd, q_cmd, drop=["time"])
    _expect(p, "no 'time' column", humanoid)
    bad_q = q.copy()
    bad_q[7, 3] = np.nan
    _write_csv(p, names, t_log, bad_q, qd, q_cmd)
    _expect(p, "q has NaN/inf at data row 8", humanoid)
    t_bad = t_log.copy()
    t_bad[5] = t_bad[4]
    _write_csv(p, names, t_bad, q, qd, q_cmd)
    _expect(p, "duplicated time stamp at data row 6", humanoid)
    t_bad[5] = t_bad[3]
    _write_csv(p, names, t_bad, q, qd, q_cmd)
    _expect(p, "decreasing time stamp", humanoid)
    p.write_text("time,q_x\n1,2\n3\n")
    _expect(p, "data row 2 has 1 fields", humanoid)
    _expect(tmp_path / "absent.csv", "log file not found", humanoid)
    (tmp_path / "log.txt").write_text("x")
    _expect(tmp_path / "log.txt", "unknown log type", humanoid)


def test_cli_imports_logs(tmp_path, humanoid):
    from wresdyn.cli import main

    names = list(humanoid.joint_names)
    t_log = np.arange(40) / 100.0
    q, qd, q_cmd, _ = _signals(names, t_log)
    _write_csv(tmp_path / "run1.csv", names, t_log, q, qd, q_cmd)
    args = ["collect", "--logs", str(tmp_path / "run1.csv"), "--split", "heldout", "--out", str(tmp_path / "o")]
    assert main(args) == 0
    ds = load_dataset(tmp_path / "o" / "dataset.npz", humanoid)
    assert [tr.name for tr in ds.split("heldout")] == ["run1"]
    args = ["collect", "--logs", str(tmp_path / "run1.csv"), "--split", "validation", "--out", str(tmp_path / "v")]
    assert main(args) == 0
    assert [tr.name for tr in load_dataset(tmp_path / "v" / "dataset.npz").split("validation")] == ["run1"]
    (tmp_path / "broken.csv").write_text("time\n0\n")
    assert main(["collect", "--logs", str(tmp_path / "broken.csv"), "--out", str(tmp_path / "o2")]) == 2
