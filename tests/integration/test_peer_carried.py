"""A peer checkpoint of the humanoid fight (``benchmarks/peers/humanoid.py``) carried to another machine: the data
lies under another path there and may be a re-recording whose header provenance differs in its last digits; the
checkpoint resumes and its best so far is reported from it, and data with other samples is refused."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest

if not hasattr(pytest.importorskip("mujoco.sysid"), "optimize"):  # its imports need the extra's packages
    pytest.skip("mujoco[sysid] extra not installed (pip install -e '.[bench]')", allow_module_level=True)

BENCH = Path(__file__).resolve().parents[2] / "benchmarks"
TINY = ["--threads", "1", "--horizon", "40", "--stages", "damping", "--max-seconds", "0"]
"""One stage of 21 parameters, paused after its first iteration in each call: each call a few seconds."""


@pytest.fixture(scope="module")
def fight():
    sys.path.insert(0, str(BENCH / "peers"))
    spec = importlib.util.spec_from_file_location("peers_humanoid_carried", BENCH / "peers" / "humanoid.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def rewrite(src: Path, dst: Path, meta=None, nudge: str | None = None) -> None:
    """``src``'s arrays into ``dst`` with the header's ``meta`` replaced, or the array ``nudge`` changed by 1e-9."""
    with np.load(src, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    header = json.loads(arrays["header"].tobytes().decode())
    if meta is not None:
        header["meta"] = meta
    arrays["header"] = np.frombuffer(json.dumps(header).encode(), dtype=np.uint8)
    if nudge is not None:
        arrays[nudge] = arrays[nudge] + 1e-9
    np.savez_compressed(dst, **arrays)


def test_checkpoint_resumes_and_reports_on_the_same_data_elsewhere(fight, data, tmp_path):
    here, there = tmp_path / "here", tmp_path / "there"
    here.mkdir()
    there.mkdir()
    data.save(str(here / "tiny.npz"))
    out = str(tmp_path / "out")
    fight.main(["peer", str(here / "tiny.npz"), "--out", out, *TINY])
    first = json.loads((tmp_path / "out" / "peer" / "checkpoint.json").read_text())
    assert not first["done"] and first["config"]["data"] == str(here / "tiny.npz")

    # another machine's recording: the same samples, the provenance's digits not
    rewrite(here / "tiny.npz", there / "tiny.npz", meta={"recorded": "elsewhere"})
    assert fight.file_digest(str(there / "tiny.npz")) != first["config"]["data_sha256"]
    fight.main(["peer", str(there / "tiny.npz"), "--out", out, *TINY, "--resume"])
    second = json.loads((tmp_path / "out" / "peer" / "checkpoint.json").read_text())
    assert len(second["calls"]) == 2 and len(second["curve"]) > len(first["curve"]) and not second["done"]

    fight.main(["report", "--out", out, "--data", str(there / "tiny.npz"), "--partial"])
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert summary["mujoco.sysid"]["converged"]["value"] is False

    key = next(k for k in np.load(here / "tiny.npz").files if k.endswith("/q"))
    rewrite(here / "tiny.npz", tmp_path / "other.npz", nudge=key)
    with pytest.raises(SystemExit) as e:
        fight.main(["report", "--out", out, "--data", str(tmp_path / "other.npz"), "--partial"])
    assert str(e.value.code).startswith("error:") and "not the data" in str(e.value.code)
    with pytest.raises(SystemExit) as e:
        fight.main(["peer", str(tmp_path / "other.npz"), "--out", out, *TINY, "--resume"])
    message = str(e.value.code)
    assert message.startswith("error:") and "not the data" in message and "\n" not in message
