"""The MCAP round trip benchmark (``benchmarks/fidelity/mcap_roundtrip.py``) at tiny size: the shipped "real"
robot's trajectories written as ROS 2 bags (one per trajectory, JointState states and commands at the recorded rate,
epoch header stamps) import through ``wresdyn collect --logs`` to the NPZ's arrays, splits, rate and joints, and
identification on both datasets learns the same parameters with the same validation figures."""

from __future__ import annotations

import importlib.util
import sys
from dataclasses import replace
from pathlib import Path

import pytest

pytest.importorskip("mcap_ros2")  # a dependency of the package; its absence is an install error, reported here

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "data" / "dataset.npz"


@pytest.fixture(scope="module")
def bench():
    path = REPO / "benchmarks" / "fidelity" / "mcap_roundtrip.py"
    spec = importlib.util.spec_from_file_location("mcap_roundtrip", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["mcap_roundtrip"] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def imported(bench, tmp_path_factory):
    """One trajectory of each split, 0.2 s, recorded as bags and imported: (the comparison, the folder)."""
    out = tmp_path_factory.mktemp("mcap_roundtrip")
    return bench.record_and_import(DATA, out, 1, 0.2), out


def test_bags_import_to_the_npz(imported):
    """Every array back to float64 rounding (measured: q 6e-17 rad, q̇ 1.4e-15 rad/s, q̈ 2.3e-13 rad/s^2), names,
    each split's runs in order, rate, joints and robot as recorded."""
    r, out = imported
    assert r["trajectories"] == 4 and r["rate_hz"] == 500.0
    assert r["data_differences"] == []
    d = r["max_abs_diff"]
    assert d["t"] == 0.0 and d["q_cmd"] == 0.0  # integer-nanosecond stamps; each command held on its own step
    assert d["q"] <= 1e-15 and d["qd"] <= 1e-13 and d["qdd"] <= 1e-11 and d["tau"] is None
    assert sorted(p.name for p in (out / "bags").glob("*.mcap")) == [
        "heldout_000.mcap", "ood_000.mcap", "train_000.mcap", "validation_000.mcap"]


def test_identification_on_both_is_the_same(bench, imported):
    """Two identification steps with the same seed on each dataset: every identified parameter, loss term and
    validation error equal (measured: bit for bit, 548 numbers)."""
    _, out = imported
    r = bench.learn_both(out, "identify", ["--iterations", "2", "--windows", "2", "--horizon-curriculum", "8"],
                         evaluate=False)
    assert r["run_numbers"] > 500 and r["fit_differences"] == []
    assert r["run_max_rel_diff"] <= 1e-12


def test_a_changed_array_or_split_is_found(bench):
    """The comparison fails where the data differ: one command changed by 1e-9 rad, or a run in another split."""
    from wresdyn.data.dataset import load_dataset

    ds = bench.subset(load_dataset(DATA), 1, 0.2)
    tr = ds.trajectories[1]
    q_cmd = tr.q_cmd.copy()
    q_cmd[10, 3] += 1e-9
    changed = replace(ds, trajectories=[ds.trajectories[0], replace(tr, q_cmd=q_cmd), *ds.trajectories[2:]])
    diffs, bad = bench.compare_data(ds, changed)
    assert diffs["q_cmd"] == pytest.approx(1e-9, rel=1e-6) and any(b.startswith("q_cmd") for b in bad)
    moved = replace(ds, trajectories=[replace(t, split="train") for t in ds.trajectories])
    assert any(b.startswith("validation split") for b in bench.compare_data(ds, moved)[1])
    worst, bad = bench.compare_fits({"a.kp": 1.0, "b": 2.0}, {"a.kp": 1.0 + 1e-6, "b": 2.0})
    assert worst == pytest.approx(1e-6) and bad == ["a.kp: 1 != 1.000001"]
