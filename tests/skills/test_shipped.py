"""Shipped skill policies: installed into a run folder with their files checked against the manifest's hashes."""

import pytest

from wresdyn.errors import WresdynError
from wresdyn.skills import shipped


def _run(folder, last=99):
    folder.mkdir(parents=True)
    for name, data in (("config.json", b"{}"), ("train_summary.json", b"{}"), ("policy.pt", b"program"),
                       ("model_50.pt", b"older"), (f"model_{last}.pt", b"latest")):
        (folder / name).write_bytes(data)
    return folder


def test_ship_install_and_check(tmp_path, monkeypatch):
    monkeypatch.setattr(shipped, "SHIPPED", tmp_path / "policies")
    folder = shipped.ship_policy(_run(tmp_path / "run"), "floor_nominal", "wresdyn deploy ...", "H200", "abc")
    # only the last checkpoint travels
    assert sorted(p.name for p in folder.iterdir()) == ["config.json", "model_99.pt", "policy.pt", "shipped.json",
                                                        "train_summary.json"]
    dst = shipped.install_policy("floor_nominal", tmp_path / "out" / "a_nominal")
    assert (dst / "model_99.pt").read_bytes() == b"latest"
    assert not (tmp_path / "out" / "a_nominal.partial").exists()
    assert shipped.install_policy("floor_nominal", dst) == dst  # the same files again: kept
    (folder / "policy.pt").write_bytes(b"tampered")
    with pytest.raises(WresdynError, match="changed since it was shipped"):
        shipped.shipped_folder("floor_nominal")
    with pytest.raises(WresdynError, match="no shipped policy 'stand'.*floor_nominal"):
        shipped.shipped_folder("stand")


def test_install_refuses_another_policy_and_unfinished_runs(tmp_path):
    dst = shipped.install_policy(_run(tmp_path / "a"), tmp_path / "out")
    with pytest.raises(WresdynError, match="holds another policy"):
        shipped.install_policy(_run(tmp_path / "b", last=120), dst)
    unfinished = _run(tmp_path / "c")
    (unfinished / "policy.pt").unlink()
    with pytest.raises(WresdynError, match="not a finished skill run.*policy.pt"):
        shipped.install_policy(unfinished, tmp_path / "out2")
