"""A CUDA device the machine does not have (no GPU, a CPU build of torch, an index past the last GPU) is refused in one
line with exit status 2 before anything is written, through the real commands (``cuda:99``: no machine has it)."""

from __future__ import annotations

import pytest

from wresdyn.cli import main

REFUSED = "error: device 'cuda:99' is not available here: Warp "


@pytest.mark.parametrize("command", [
    ["fit", "data/dataset.npz", "--iterations", "1", "--identify.iterations", "1"],
    ["identify", "data/dataset.npz", "--iterations", "1"],
    ["train", "data/dataset.npz", "--iterations", "1"],
    ["deploy", "data/dataset.npz", "--floor"],
    ["bench", "--worlds", "4", "--json"],
    ["warmup", "--export"],
])
def test_a_missing_cuda_device_is_one_line_and_leaves_no_output(command, tmp_path, capsys):
    out = tmp_path / "out"
    written = [str(out)] if command[-1] in ("--json", "--export") else ["--out", str(out)]
    assert main([*command, *written, "--device", "cuda:99"]) == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if not line.startswith("Warp CUDA warning")]
    assert lines[-1].startswith(f"wresdyn {command[0]}: {REFUSED}")
    assert "CUDA device(s), torch " in lines[-1] and "use --device cpu" in lines[-1]
    assert not any("Traceback" in line for line in lines)
    assert not out.exists()


def test_a_missing_beside_device_is_refused_before_the_corrections_are_fitted(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["deploy", "data/dataset.npz", "--floor", "--beside-devices", "cuda:99", "--out", str(out)]) == 2
    assert capsys.readouterr().err.splitlines()[-1].startswith(f"wresdyn deploy: {REFUSED}")
    assert not out.exists()
