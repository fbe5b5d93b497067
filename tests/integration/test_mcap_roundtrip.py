"""The MCAP round trip benchmark (``benchmarks/fidelity/mcap_roundtrip.py``) at tiny size: the shipped "real"
robot's trajectories written as ROS 2 bags import to the NPZ's arrays, splits, rate and joints, and identification
on both datasets gives the same figures."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

pytest.importorskip("mcap_ros2")  # a dependency of the package; its absence is an install error, reported here

REPO = Path(__file__).resolve().parents[2]
DATA = REPO / "data" / "dataset.npz"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("mcap_roundtrip", REPO / "benchmarks" / "fidelity" / "mcap_roundtrip.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["mcap_roundtrip"] = module
    spec.loader.exec_module(module)
    return module


def test_bags_import_to_the_npz_and_identify_alike(bench, tmp_path, capsys):
    """One trajectory of each split, 0.4 s: every array back to float64 rounding (measured: q 5e-16 rad, q̇ 1e-14
    rad/s, q̈ 7e-13 rad/s^2 on 1 s), names, splits and rate as recorded; two identification steps with the same seed
    on each give the same validation, held-out and OOD figures (measured: equal to 1e-16 relative)."""
    r = bench.roundtrip(DATA, tmp_path, 1, 0.4, "identify",
                        ["--iterations", "2", "--windows", "2", "--horizon-curriculum", "8"])
    assert r["trajectories"] == 4 and r["rate_hz"] == 500.0
    assert r["data_differences"] == []
    d = r["max_abs_diff"]
    assert d["t"] == 0.0 and d["q_cmd"] == 0.0  # integer-nanosecond stamps; commands held on the same steps
    assert d["q"] <= 1e-14 and d["qd"] <= 1e-12 and d["qdd"] <= 1e-10 and d["tau"] is None
    assert r["fit_differences"] == [] and r["fit_max_rel_diff"] <= 1e-12
    npz, mcap = r["figures"]["npz"], r["figures"]["mcap"]
    assert sorted(npz) == ["heldout", "ood", "validation"]
    assert all(npz[s]["calibrated"] == pytest.approx(mcap[s]["calibrated"], rel=1e-12) for s in npz)
    assert "imported 4 run(s)" not in capsys.readouterr().out  # --quiet import: the benchmark prints its own lines


def test_a_changed_bag_is_found(bench, tmp_path):
    """The comparison fails where the data differ: one command changed by 1e-9 rad in one bag."""
    from dataclasses import replace

    from wresdyn.data.dataset import load_dataset

    ds = bench.subset(load_dataset(DATA), 1, 0.2)
    tr = ds.trajectories[1]
    q_cmd = tr.q_cmd.copy()
    q_cmd[10, 3] += 1e-9
    changed = replace(ds, trajectories=[ds.trajectories[0], replace(tr, q_cmd=q_cmd), *ds.trajectories[2:]])
    diffs, bad = bench.compare_data(ds, changed)
    assert diffs["q_cmd"] == pytest.approx(1e-9, rel=1e-6) and any(b.startswith("q_cmd") for b in bad)
    moved = replace(ds, trajectories=[replace(t, split="train") for t in ds.trajectories])
    assert any("validation split" in b for b in bench.compare_data(ds, moved)[1])
