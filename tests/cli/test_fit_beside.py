"""The fit's ONNX export beside its evaluation (CPU) or after it (GPU): the files are those of the export in one go,
and an error in either is raised, not lost in the thread."""

import filecmp
import threading
import types

import numpy as np
import pytest
import torch

from wresdyn.cli.fit import onnx_with_evaluation, run_beside
from wresdyn.learn.residual import MLPResidualPolicy, export_run_files

FILES = ("policy.pt", "policy.onnx", "residual.json")


def test_the_onnx_written_later_is_the_same_file(tmp_path):
    n = 2
    torch.manual_seed(0)
    policy = MLPResidualPolicy(torch.nn.Linear(4 * n, n), np.zeros(4 * n), np.ones(4 * n), np.full(n, 3.0), "torque")
    data = types.SimpleNamespace(joint_names=["a", "b"], rate_hz=500.0)
    now, later = tmp_path / "now", tmp_path / "later"
    assert export_run_files(policy, now, data, arch="mlp") is None
    write_onnx = export_run_files(policy, later, data, onnx_later=True, arch="mlp")
    assert not (later / "policy.onnx").exists()  # left to the caller
    assert (later / "policy.pt").exists() and (later / "residual.json").exists()
    run_beside(write_onnx, lambda: None)
    for name in FILES:
        assert filecmp.cmp(now / name, later / name, shallow=False), name


def test_both_run_at_once_and_the_work_result_is_returned():
    started = threading.Event()

    def background():
        assert started.wait(30), "the work did not run while the background call did"

    def work():
        started.set()
        return 7

    assert run_beside(background, work) == 7


def test_a_background_error_is_raised():
    def background():
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        run_beside(background, lambda: 1)


def test_the_work_error_wins_after_the_background_finished():
    finished = []

    def background():
        finished.append(True)

    def work():
        raise ValueError("evaluation failed")

    with pytest.raises(ValueError, match="evaluation failed"):
        run_beside(background, work)
    assert finished == [True]


@pytest.mark.parametrize("device", ["cpu", "cuda:0", "cuda"])
def test_the_onnx_is_written_beside_a_cpu_evaluation_and_after_a_gpu_one(device):
    events = []  # (what, in the main thread)

    def write_onnx():
        events.append(("onnx", threading.current_thread() is threading.main_thread()))

    def evaluate():
        if device == "cpu":  # beside: the export runs while the evaluation does
            assert _wait_for(events), "the export did not run beside the evaluation"
        events.append(("eval", threading.current_thread() is threading.main_thread()))
        return 3

    assert onnx_with_evaluation(write_onnx, evaluate, device) == 3
    if device == "cpu":
        assert events == [("onnx", False), ("eval", True)]
    else:  # one after the other, here
        assert events == [("eval", True), ("onnx", True)]


def _wait_for(events, seconds=30.0):
    import time

    end = time.monotonic() + seconds
    while not events and time.monotonic() < end:
        time.sleep(0.001)
    return bool(events)
