"""Dataset format: exact save/load round trip, every validation error, atomic writes, reproducible collection,
schema-1 files and their migration to schema 2."""

import json
from pathlib import Path

import numpy as np
import pytest

from wresdyn.data.dataset import (
    SCHEMA_VERSION,
    SPLITS,
    Dataset,
    DatasetError,
    Trajectory,
    derive_qdd,
    load_dataset,
    read_header,
)

RATE = 500.0
NAMES = ["j_a", "j_b", "j_c"]


def _traj(name, split, n=40, seed=0, tau=True, derived=False):
    rng = np.random.default_rng(seed)
    t = np.arange(n) / RATE
    q = rng.standard_normal((n, 3))  # float64 values that float32 cannot hold: stored as float64
    qd = rng.standard_normal((n, 3)).astype(np.float32)  # float32-exact: stored as float32
    qdd = derive_qdd(qd, RATE) if derived else rng.standard_normal((n, 3))
    return Trajectory(name, split, t, q, qd, qdd, rng.standard_normal((n, 3)),
                      rng.standard_normal((n, 3)) if tau else None)


def _dataset(**kw):
    trajs = [_traj("a", "train", seed=1), _traj("b", "heldout", seed=2, tau=False),
             _traj("c", "ood", n=55, seed=3, derived=True), _traj("v", "validation", seed=4)]
    args = dict(joint_names=list(NAMES), rate_hz=RATE, trajectories=trajs, robot_file="robot.usda",
                robot_sha256="0" * 64, mismatch={"friction": 0.1, "seed": 7}, seed=42,
                meta={"nested": {"x": [1.5, 2.0]}, "np": np.float64(0.25)})
    args.update(kw)
    return Dataset(**args)


def _assert_same(a: Dataset, b: Dataset):
    assert a.joint_names == b.joint_names and a.rate_hz == b.rate_hz and a.seed == b.seed
    assert a.robot_file == b.robot_file and a.robot_sha256 == b.robot_sha256 and a.mismatch == b.mismatch
    assert [t.name for t in a.trajectories] == [t.name for t in b.trajectories]
    for x, y in zip(a.trajectories, b.trajectories):
        assert x.split == y.split
        for f in ("t", "q", "qd", "qdd", "q_cmd", "tau"):
            u, v = getattr(x, f), getattr(y, f)
            assert (u is None) == (v is None), f
            if u is not None:
                assert v.dtype == np.float64
                np.testing.assert_array_equal(u, v, err_msg=f"{x.name}.{f}")


def test_round_trip_is_exact(tmp_path):
    ds = _dataset()
    path = tmp_path / "d.npz"
    ds.save(path)
    back = load_dataset(path)
    _assert_same(ds, back)
    assert back.meta == {"nested": {"x": [1.5, 2.0]}, "np": 0.25}
    assert SPLITS == ("train", "validation", "heldout", "ood")
    assert [len(back.split(s)) for s in SPLITS] == [1, 1, 1, 1] and back.split("validation")[0].name == "v"
    with np.load(path) as z:  # float32 where exact, float64 otherwise; derived q̈ is not stored
        assert z["traj/0000/qd"].dtype == np.float32 and z["traj/0000/q"].dtype == np.float64
        assert "traj/0002/qdd" not in z.files and "traj/0000/qdd" in z.files
        header = json.loads(z["header"].tobytes())
    assert header["schema_version"] == SCHEMA_VERSION == 2 and header["units"]["qd"] == "rad/s"


def test_derive_qdd_matches_the_analytic_derivative():
    """q̇ = sin(2π f t) -> q̈ = 2π f cos(2π f t); the quadratic Savitzky-Golay fit over 22 ms has a bias of
    order (ω h)² / 6 ≈ 1e-3 relative at 2 Hz, so 1 % is a loose but failing-on-error bound."""
    t = np.arange(1000) / RATE
    w = 2 * np.pi * 2.0
    qdd = derive_qdd(np.sin(w * t)[:, None], RATE)[:, 0]
    np.testing.assert_allclose(qdd, w * np.cos(w * t), atol=0.01 * w)


def _write_raw(path: Path, header: dict, arrays: dict):
    arrays = dict(arrays)
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    np.savez(path, **arrays)


def _raw(ds: Dataset, path: Path):
    """Save ``ds`` and return its header and arrays, ready to be tampered with."""
    ds.save(path)
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files if k != "header"}
        header = json.loads(z["header"].tobytes())
    return header, arrays


def _expect(path, match, robot=None):
    with pytest.raises(DatasetError, match=match) as e:
        load_dataset(path, robot)
    msg = str(e.value)
    assert str(path) in msg and "\n" not in msg, msg
    return msg


def test_missing_and_garbage_files(tmp_path):
    _expect(tmp_path / "nope.npz", "not found")
    junk = tmp_path / "junk.npz"
    junk.write_bytes(b"this is not a zip file")
    msg = _expect(junk, "not a wresdyn dataset")
    assert "not a NumPy .npz archive" in msg and "allow_pickle" not in msg  # NumPy's hint to unpickle is not passed on
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, header=np.array([{"a": 1}], dtype=object))
    msg = _expect(pickled, "not a wresdyn dataset")
    assert "pickled objects, which are never loaded" in msg and "allow_pickle" not in msg
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    _expect(tmp_path / "other.npz", "no header")


@pytest.mark.parametrize("field,row", [("q", 5), ("q_cmd", 0), ("qd", 39), ("tau", 17)])
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_non_finite_rows(tmp_path, field, row, bad):
    header, arrays = _raw(_dataset(), tmp_path / "ok.npz")
    a = arrays[f"traj/0000/{field}"].astype(np.float64)
    a[row, 1] = bad
    arrays[f"traj/0000/{field}"] = a
    _write_raw(tmp_path / "bad.npz", header, arrays)
    msg = _expect(tmp_path / "bad.npz", f"{field} has NaN/inf")
    assert f"first at row {row}" in msg and "'a'" in msg


def test_time_errors(tmp_path):
    header, arrays = _raw(_dataset(), tmp_path / "ok.npz")
    cases = {"duplicated time stamp": lambda t: np.concatenate([t[:10], t[9:-1]]),
             "not increasing at row 10": lambda t: np.concatenate([t[:9], t[10:11], t[9:10], t[11:]]),
             "do not match rate_hz": lambda t: t * 2.0}
    for match, change in cases.items():
        arr = dict(arrays)
        arr["traj/0001/t"] = change(arrays["traj/0001/t"])
        _write_raw(tmp_path / "bad.npz", header, arr)
        _expect(tmp_path / "bad.npz", match)
    # a header rate that is not the file's: 250 Hz stamps declared as 500 Hz
    h = dict(header, rate_hz=250.0)
    _write_raw(tmp_path / "bad.npz", h, arrays)
    assert "median 500 Hz" in _expect(tmp_path / "bad.npz", "do not match rate_hz = 250")


def test_shape_and_header_errors(tmp_path):
    header, arrays = _raw(_dataset(), tmp_path / "ok.npz")
    cases = [
        (header, {**arrays, "traj/0000/q": arrays["traj/0000/q"][:, :2]}, r"q must have shape \(40, 3\)"),
        (header, {**arrays, "traj/0000/q_cmd": arrays["traj/0000/q_cmd"][:-1]}, "q_cmd must have shape"),
        (header, {**arrays, "traj/0000/t": arrays["traj/0000/t"][:, None]}, "t must have shape"),
        (header, {k: v for k, v in arrays.items() if k != "traj/0001/qd"}, "has no qd array"),
        ({**header, "schema_version": 99}, arrays, "schema version 99 is not supported"),
        ({**header, "schema_version": 3}, arrays, "schema version 3 is not supported"),
        ({**header, "schema_version": True}, arrays, "schema version True is not supported"),
        ({k: v for k, v in header.items() if k != "schema_version"}, arrays, "schema version None"),
        ({**header, "joint_names": ["j_a", "j_a", "j_c"]}, arrays, "duplicated joint name"),
        ({**header, "rate_hz": -5}, arrays, "rate_hz must be a positive"),
        ({**header, "trajectories": [dict(header["trajectories"][0], split="test")]}, arrays, "unknown split 'test'"),
        ({k: v for k, v in header.items() if k != "robot_sha256"}, arrays, "'robot_sha256' is missing"),
    ]
    for h, arr, match in cases:
        _write_raw(tmp_path / "bad.npz", h, arr)
        _expect(tmp_path / "bad.npz", match)


def test_joint_names_against_the_robot(tmp_path, humanoid):
    n = humanoid.n_dof
    names = list(humanoid.joint_names)
    perm = np.random.default_rng(0).permutation(n)
    t = np.arange(30) / RATE
    base = np.arange(30)[:, None] + 100.0 * np.arange(n)[None]  # column j holds 100 j + k: traceable
    tr = Trajectory("x", "train", t, base[:, perm], base[:, perm], base[:, perm], base[:, perm])
    ds = Dataset([names[i] for i in perm], RATE, [tr], str(humanoid.source), humanoid.source_sha256)
    ds.save(tmp_path / "perm.npz")
    back = load_dataset(tmp_path / "perm.npz", humanoid)
    assert back.joint_names == names
    np.testing.assert_array_equal(back.trajectories[0].q, base)  # mapped by name into the robot's order
    renamed = Dataset(["mystery_joint"] + names[1:], RATE, [Trajectory("x", "train", t, base, base, base, base)],
                      str(humanoid.source), humanoid.source_sha256)
    renamed.save(tmp_path / "unknown.npz")
    _expect(tmp_path / "unknown.npz", r"\['mystery_joint'\] are not joints of humanoid", humanoid)
    short = Dataset(names[:-1], RATE, [Trajectory("x", "train", t, base[:, :-1], base[:, :-1], base[:, :-1],
                                                  base[:, :-1])], str(humanoid.source), humanoid.source_sha256)
    short.save(tmp_path / "missing.npz")
    _expect(tmp_path / "missing.npz", rf"\['{names[-1]}'\] of humanoid.usda are missing", humanoid)
    with pytest.warns(UserWarning, match="another hash"):
        Dataset(names, RATE, [Trajectory("x", "train", t, base, base, base, base)], "elsewhere.usda",
                "f" * 64).for_robot(humanoid)


def test_save_is_atomic(tmp_path):
    path = tmp_path / "d.npz"
    good = _dataset()
    good.save(path)
    before = path.read_bytes()
    bad = _dataset()
    bad.trajectories[0].q[3, 0] = np.nan
    with pytest.raises(DatasetError, match="NaN"):
        bad.save(path)
    unserialisable = _dataset(meta={"callback": object()})
    with pytest.raises(DatasetError, match="not JSON-serialisable"):
        unserialisable.save(path)
    assert path.read_bytes() == before  # the old file is untouched
    assert sorted(p.name for p in tmp_path.iterdir()) == ["d.npz"]  # and no temporary file is left
    with pytest.raises(DatasetError, match="NaN"):
        bad.save(tmp_path / "new.npz")
    assert not (tmp_path / "new.npz").exists()
    with pytest.raises(DatasetError, match="does not exist"):
        good.save(tmp_path / "no_such_dir" / "d.npz")


def test_unknown_split_query():
    with pytest.raises(DatasetError, match="unknown split 'test'"):
        _dataset().split("test")


def test_collected_dataset_round_trips_and_is_reproducible(tmp_path, humanoid):
    """The real pipeline, tiny: same seed gives the same data, another seed other data, and the file is exact."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import collect

    mm = Mismatch.load(Path(__file__).resolve().parents[2] / "data" / "mismatch_default.toml")
    counts = {"train": 1, "ood": 2}
    a = collect(humanoid, mm, counts, duration=0.5, seed=3)
    b = collect(humanoid, mm, counts, duration=0.5, seed=3)
    c = collect(humanoid, mm, {"train": 1}, duration=0.5, seed=4)
    _assert_same(a, b)
    assert np.abs(a.trajectories[0].q_cmd - c.trajectories[0].q_cmd).max() > 1e-3
    assert [tr.name for tr in a.trajectories] == ["train_000", "ood_000", "ood_001"]
    assert a.meta["trajectory_params"]["ood_001"]["family"] == "kick"
    a.save(tmp_path / "a.npz")
    back = load_dataset(tmp_path / "a.npz", humanoid)
    _assert_same(a, back)
    assert back.mismatch == mm.to_dict() and back.seed == 3
    tr = back.trajectories[0]
    np.testing.assert_array_equal(tr.t, np.arange(250) / RATE)
    assert tr.tau is not None and np.abs(tr.q - tr.q_cmd).max() < 0.5


def _save_v1(ds: Dataset, path: Path) -> None:
    """Write ``ds`` as a schema-1 file: the same layout with version 1 (which has no validation split)."""
    header, arrays = _raw(ds, path.with_name(path.name + ".v2.npz"))
    path.with_name(path.name + ".v2.npz").unlink()
    _write_raw(path, {**header, "schema_version": 1}, arrays)


def _without_validation(ds: Dataset) -> Dataset:
    from dataclasses import replace

    return replace(ds, trajectories=[tr for tr in ds.trajectories if tr.split != "validation"])


def test_schema_1_files_load(tmp_path):
    v1 = _without_validation(_dataset())
    _save_v1(v1, tmp_path / "v1.npz")
    assert read_header(tmp_path / "v1.npz")["schema_version"] == 1
    back = load_dataset(tmp_path / "v1.npz")
    _assert_same(v1, back)
    assert back.split("validation") == []
    back.save(tmp_path / "v2.npz")  # saving always writes the current schema
    assert read_header(tmp_path / "v2.npz")["schema_version"] == 2
    # schema 1 has no validation split: a version-1 file that claims one is refused
    header, arrays = _raw(_dataset(), tmp_path / "tmp.npz")
    _write_raw(tmp_path / "bad.npz", {**header, "schema_version": 1}, arrays)
    _expect(tmp_path / "bad.npz", r"trajectory 'v' has split 'validation', which schema version 1 does not have")


def test_migrate_log_dataset_moves_train_to_validation(tmp_path, capsys):
    """Real logs (no mismatch, no seed) cannot record more: the last K training trajectories become validation."""
    from wresdyn.cli import main
    from wresdyn.data.schema_migration import migrate

    trajs = [_traj(f"run{i}", "train", seed=i) for i in range(4)] + [_traj("h", "heldout", seed=9)]
    logs = Dataset(list(NAMES), RATE, trajs, "robot.usda", "0" * 64, {}, None, {"source_logs": []})
    old = tmp_path / "logs_v1.npz"
    _save_v1(logs, old)
    m = migrate(old, 2)
    assert (m.from_version, m.how, m.names, m.robot) == (1, "moved from train", ["run2", "run3"], None)
    assert [(tr.name, tr.split) for tr in m.dataset.trajectories] == [
        ("run0", "train"), ("run1", "train"), ("run2", "validation"), ("run3", "validation"), ("h", "heldout")]
    assert m.dataset.meta["migration"]["validation"] == "moved from train"
    new = tmp_path / "logs_v2.npz"
    assert main(["migrate", str(old), "--out", str(new), "--validation", "2"]) == 0
    assert "moved the last 2 training trajectories to validation (run2, run3)" in capsys.readouterr().out
    back = load_dataset(new)
    assert read_header(new)["schema_version"] == 2 and [tr.name for tr in back.split("validation")] == ["run2", "run3"]
    by_name = {tr.name: tr for tr in back.trajectories}
    for tr in logs.trajectories:
        np.testing.assert_array_equal(tr.q, by_name[tr.name].q)  # only the split changed
    # an existing output is refused without --force and left as it was; with --force it is replaced
    before = new.read_bytes()
    assert main(["migrate", str(old), "--out", str(new), "--validation", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("wresdyn migrate: error:") and "--force" in err and "\n" not in err
    assert new.read_bytes() == before
    assert main(["migrate", str(old), "--out", str(new), "--validation", "1", "--force"]) == 0
    assert [tr.name for tr in load_dataset(new).split("validation")] == ["run3"]
    # errors leave nothing behind: all of train asked for, an input already at schema 2
    for args, match in [([str(old), "--validation", "4"], "at least one must stay in train"),
                        ([str(new)], "already schema version 2")]:
        assert main(["migrate", *args, "--out", str(tmp_path / "x.npz")]) == 2
        err = capsys.readouterr().err.strip()
        assert match in err and "\n" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["logs_v1.npz", "logs_v2.npz"]


@pytest.fixture(scope="module")
def collected(humanoid):
    """A tiny collect with a validation split (0.1 s per trajectory, the real pipeline)."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import collect

    mm = Mismatch.load(Path(__file__).resolve().parents[2] / "data" / "mismatch_default.toml")
    return collect(humanoid, mm, {"train": 1, "validation": 2, "heldout": 1}, duration=0.1, seed=5)


def test_migrate_simulated_dataset_records_validation(tmp_path, humanoid, collected, capsys):
    """A schema-1 collect file (same data less validation) migrated with --validation 2 is the schema-2 collect:
    the recorded validation trajectories are bit for bit those ``collect`` records."""
    from wresdyn.cli import main
    from wresdyn.data.schema_migration import migrate

    old = tmp_path / "sim_v1.npz"
    _save_v1(_without_validation(collected), old)
    m = migrate(old, 2, humanoid)
    assert (m.how, m.names, m.robot) == ("recorded", ["validation_000", "validation_001"], humanoid)
    _assert_same(collected, m.dataset)
    assert m.dataset.meta["trajectory_params"] == collected.meta["trajectory_params"]
    assert m.dataset.meta["migration"] == {"from_schema_version": 1, "to_schema_version": 2, "validation": "recorded",
                                           "trajectories": ["validation_000", "validation_001"]}
    # through the command line: the robot comes from the header, the file is exact
    new = tmp_path / "sim_v2.npz"
    assert main(["migrate", str(old), "--out", str(new), "--validation", "1", "--no-gap"]) == 0
    assert "recorded 1 validation trajectories (validation_000)" in capsys.readouterr().out
    back = load_dataset(new)
    np.testing.assert_array_equal(back.split("validation")[0].q, collected.split("validation")[0].q)
    # another robot than the recording's (here: the mismatch draws another set of link and gain errors) is
    # caught by the re-recorded trajectory, and nothing is written
    header, arrays = _raw(_without_validation(collected), tmp_path / "tmp.npz")
    (tmp_path / "tmp.npz").unlink()
    _write_raw(tmp_path / "other.npz", {**header, "schema_version": 1,
                                        "mismatch": {**header["mismatch"], "seed": 8}}, arrays)
    assert main(["migrate", str(tmp_path / "other.npz"), "--out", str(tmp_path / "x.npz"), "--validation", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert "re-recording train_000 does not reproduce it" in err and "\n" not in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["other.npz", "sim_v1.npz", "sim_v2.npz"]
