"""``benchmarks/speed/physical_limit.py``'s ``mjwarp-testspeed`` step, with a stand-in for the subprocess (the real one
refuses the CPU): it asks mujoco_warp to keep going past a line search's iteration cap, counts the warnings that
prints, reads the steps/s from the JSON line, keeps a long output's head and tail, and records a failing run's error."""

import importlib.util
import json
import subprocess
from pathlib import Path
from types import SimpleNamespace

ROOT = Path(__file__).resolve().parents[2]


def _script():
    spec = importlib.util.spec_from_file_location("physical_limit", ROOT / "benchmarks/speed/physical_limit.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _fake(stdout: str, rc: int = 0):
    calls = []

    def run(cmd, **kw):
        calls.append(cmd)
        return SimpleNamespace(returncode=rc, stdout=stdout, stderr="")
    return run, calls


def test_continues_past_the_line_search_cap(tmp_path, monkeypatch):
    script = _script()
    warning = script.LS_WARNING + " - please increase ls_iterations beyond 50\n"
    run, calls = _fake(warning * 300 + json.dumps({"steps_per_second": 1.5e8}) + "\n")
    monkeypatch.setattr(subprocess, "run", run)
    res = script.mujoco_warp(tmp_path, "cuda:0", 64, 10, 5.0, "continue", ("-o", "opt.ls_iterations=100"))
    assert "--overflow_behavior=continue" in calls[0] and calls[0][-2:] == ["-o", "opt.ls_iterations=100"]
    assert res["mujoco_warp_steps_per_s"] == 1.5e8 and res["mujoco_warp_overflow_warnings"] == 300
    raw = (tmp_path / "mjwarp_testspeed_64.txt").read_text()
    # 301 lines: the first 100 and the last 100 (99 warnings and the JSON line) kept
    assert "[... 101 lines left out ...]" in raw and raw.count(script.LS_WARNING) == 199 and "steps_per_second" in raw


def test_an_aborted_run_records_its_error(tmp_path, monkeypatch):
    script = _script()
    run, calls = _fake("Simulation aborted: overflow detected in 1 world:\n  World 7: LS_ITERATIONS\n", rc=1)
    monkeypatch.setattr(subprocess, "run", run)
    res = script.mujoco_warp(tmp_path, "cuda:0", 64, 10, 5.0, "error")
    assert "--overflow_behavior=error" in calls[0]
    assert res["mujoco_warp_error"] == "exit 1:   World 7: LS_ITERATIONS" and "mujoco_warp_steps_per_s" not in res
