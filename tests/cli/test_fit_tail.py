"""The fit's helper processes (``wresdyn.cli.fit_tail``): the exported residual and the figures they write are the
bytes this process writes, a failed job fails the command in one line and leaves no half-written file, and a real
``wresdyn fit --eval`` with one or three helpers writes every file of the run in one process."""

import filecmp
import json
import re
import types

import numpy as np
import pytest
import torch

from wresdyn.cli import UserError, main
from wresdyn.cli.fit import HELPERS_ENV, helper_count
from wresdyn.cli.fit_tail import Helper
from wresdyn.data.mismatch import Mismatch
from wresdyn.evaluation.evaluate_run import _plotted
from wresdyn.evaluation.plots import plot_fig3
from wresdyn.learn.residual import GRUResidualPolicy, MLPResidualPolicy, export_run_files

TIMING = {"wall", "wall_s", "residual_wall_s", "identify_wall_s", "seconds", "elapsed", "time", "wall_clock"}
"""Keys of the run's JSON files and checkpoints that hold wall-clock times: no two runs share them."""


def _policy(arch: str, n: int = 2):
    torch.manual_seed(0)
    stats = np.zeros(4 * n), np.ones(4 * n), np.full(n, 3.0)
    if arch == "gru":
        return GRUResidualPolicy(torch.nn.GRU(4 * n, 3), torch.nn.Linear(3, n), *stats, "torque").eval()
    return MLPResidualPolicy(torch.nn.Linear(4 * n, n), *stats, "torque").eval()


@pytest.mark.parametrize("arch", ["mlp", "gru"])
def test_the_helpers_export_is_the_files_written_here(tmp_path, arch):
    policy = _policy(arch)
    data = types.SimpleNamespace(joint_names=["a", "b"], rate_hz=500.0)
    here, there = tmp_path / "here", tmp_path / "there"
    export_run_files(policy, here, data, arch=arch)
    job = export_run_files(policy, there, data, archive_later=True, arch=arch)
    assert sorted(p.name for p in there.iterdir()) == ["residual.json"]  # the rest is the job's
    with Helper() as helper:
        helper.submit(job.args[1:], job.func, *job.args)
    assert sorted(p.name for p in there.iterdir()) == sorted(p.name for p in here.iterdir())
    for name in ("policy.pt", "policy.onnx", "residual.json"):
        assert filecmp.cmp(here / name, there / name, shallow=False), name


def test_the_helpers_figure_is_the_one_drawn_here(tmp_path):
    rng = np.random.default_rng(0)
    robot = types.SimpleNamespace(joint_names=[f"j{i}" for i in range(4)], source="x")
    traj = types.SimpleNamespace(q=rng.normal(size=(50, 4)), name="t0", other=object())  # not picklable: dropped
    runs = {k: types.SimpleNamespace(q=rng.normal(size=(3, 50, 4)), qd=None) for k in ("pd", "residual")}
    weights = np.array([1.0, 0.0, 1.0, 1.0])
    plot_fig3(robot, traj, runs, tmp_path / "here.png", 100.0, 2, title="t", weights=weights)
    there = tmp_path / "there.png"
    with Helper() as helper:
        helper.submit(there, plot_fig3, *_plotted(robot, traj, runs), there, 100.0, 2, title="t", weights=weights)
    assert filecmp.cmp(tmp_path / "here.png", there, shallow=False)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["here.png", "there.png"]


@pytest.mark.parametrize("processes", [1, 2])
def test_a_failed_job_fails_the_command_in_one_line_and_leaves_no_file(tmp_path, processes):
    helper = Helper(processes)
    # numpy writes the header, then meets the bad format: a file half written
    rows = np.array([[1.0, 2.0]])
    helper.submit(tmp_path / "a.txt", np.savetxt, tmp_path / "a.txt", rows, fmt=["%d", "%q"], header="half")
    # the same helper's next job with one (not run), the other helper's with two (run)
    helper.submit(tmp_path / "b.txt", np.savetxt, tmp_path / "b.txt", rows)
    with pytest.raises(UserError) as failed:
        helper.close()
    message = str(failed.value)
    assert "\n" not in message and message.endswith("ValueError: unsupported format character 'q' (0x71) at index 4")
    assert sorted(p.name for p in tmp_path.iterdir()) == ([] if processes == 1 else ["b.txt"])


def test_a_failed_command_ends_the_helper_and_leaves_no_file(tmp_path):
    with pytest.raises(ValueError):
        with Helper() as helper:
            helper.submit(tmp_path / "x.png", plot_fig3, None, None, {}, tmp_path / "x.png", 1.0)
            raise ValueError("the fit failed")
    assert all(proc.returncode is not None for proc in helper._procs)
    assert list(tmp_path.iterdir()) == []


def test_the_number_of_helpers(monkeypatch):
    monkeypatch.delenv(HELPERS_ENV, raising=False)
    assert [helper_count(c) for c in (1, 2, 3, 4, 7, 8, 16)] == [0, 0, 0, 1, 1, 3, 3]
    monkeypatch.setenv(HELPERS_ENV, "3")
    assert helper_count(2) == 3


def _same(a, b) -> bool:
    """Two values of the run's files alike but for their wall-clock times."""
    if isinstance(a, dict) and isinstance(b, dict):
        return set(a) - TIMING == set(b) - TIMING and all(_same(a[k], b[k]) for k in set(a) - TIMING)
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if isinstance(a, torch.Tensor):
        return isinstance(b, torch.Tensor) and a.dtype == b.dtype and bool(torch.equal(a, b))
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b)
    return a == b


def _log(path) -> list[str]:
    return [re.sub(r"\b\d+(\.\d+)? ?s\b", "S", ln) for ln in path.read_text().splitlines() if "elapsed" not in ln]


def _fit(tmp_path, data, name, helpers, monkeypatch):
    """The run in ``tmp_path / name``, fitted in ``tmp_path / "fit"`` (the files record their folder)."""
    monkeypatch.setenv(HELPERS_ENV, str(helpers))
    run = tmp_path / "fit"
    assert main(["fit", str(data), "--out", str(run), "--iterations", "2", "--identify.iterations", "2", "--eval",
                 "--quiet"]) == 0
    return run.rename(tmp_path / name)


def test_a_fit_with_its_evaluation_writes_the_files_of_one_process(tmp_path, cartpole, record, monkeypatch):
    data = record(cartpole, Mismatch(), {"train": 2, "validation": 1, "heldout": 1, "ood": 1}, 0.4)
    data.gains = cartpole.gains_record()
    data.save(tmp_path / "cart.npz")
    one = _fit(tmp_path, tmp_path / "cart.npz", "one", 0, monkeypatch)
    names = sorted(str(p.relative_to(one)) for p in one.rglob("*") if p.is_file())
    assert {"policy.pt", "policy.onnx", "eval/fig4_learning_curves.png", "eval/fig3_ood.png", "eval/report.md",
            "eval/metrics.json"} <= set(names)
    for helpers in (1, 3):
        run = _fit(tmp_path, tmp_path / "cart.npz", f"helpers{helpers}", helpers, monkeypatch)
        assert sorted(str(p.relative_to(run)) for p in run.rglob("*") if p.is_file()) == names
        for name in names:
            a, b = one / name, run / name
            if filecmp.cmp(a, b, shallow=False):
                continue
            assert not name.startswith(("eval/", "policy.")), f"{name} differs"  # no clock in them: byte for byte
            if name.endswith(".json"):  # the train summary's and curves' seconds
                assert _same(json.loads(a.read_text()), json.loads(b.read_text())), name
            elif name.endswith((".log", ".md")):  # the seconds a line reports
                assert _log(a) == _log(b), name
            elif name.endswith("checkpoint.pt") or name.endswith("best.pt"):
                assert _same(*(torch.load(p, map_location="cpu", weights_only=False) for p in (a, b))), name
            else:
                pytest.fail(f"{name} differs")


def test_a_failed_helper_fails_the_fit_in_one_line_and_leaves_no_half_written_file(tmp_path, cartpole, record,
                                                                                   monkeypatch, capfd):
    data = record(cartpole, Mismatch(), {"train": 2, "validation": 1, "heldout": 1, "ood": 1}, 0.4)
    data.gains = cartpole.gains_record()
    data.save(tmp_path / "cart.npz")
    run = tmp_path / "fit"
    (run / "policy.onnx").mkdir(parents=True)  # the helper's ONNX file cannot take its place
    monkeypatch.setenv(HELPERS_ENV, "1")
    capfd.readouterr()
    assert main(["fit", str(tmp_path / "cart.npz"), "--out", str(run), "--iterations", "2", "--identify.iterations",
                 "2", "--eval", "--quiet"]) == 2
    errors = [ln for ln in capfd.readouterr().err.splitlines() if "rror" in ln]
    assert len(errors) == 1 and errors[0].startswith("wresdyn fit: error: the fit's helper process"), errors
    assert "IsADirectoryError" in errors[0] and "policy.onnx" in errors[0]
    assert not [p for p in run.rglob("*") if ".part" in p.name]
    assert (run / "policy.onnx").is_dir()
