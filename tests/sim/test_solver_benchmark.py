"""``wresdyn bench`` (:mod:`wresdyn.sim.solver_benchmark`) on a tiny problem: every row it measures, for every world
count, in the printed table and the JSON file. Sizes and timing windows are tiny; no figure is compared with a speed."""

from __future__ import annotations

import json
import math
import re

from wresdyn.cli import main
from wresdyn.sim.solver_benchmark import _fmt

ROWS = ["replay rollout", "replay step", "featherstone", "mujoco-c"]
"""Rows of a CPU run (mujoco-warp runs on CUDA only)."""


def test_bench_measures_every_row_for_every_world_count(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(["bench", "--robot", "newton:cartpole.urdf", "--gains", "examples/gains/cartpole.toml",
                 "--worlds", "1,3", "--steps", "4", "--horizon", "2", "--slow-steps", "2", "--slow-max-worlds", "1",
                 "--threads", "1", "--min-time", "0.01", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    res = json.loads(out.read_text())
    assert res["robot"] == "cartpole.urdf" and (res["dt"], res["steps"], res["horizon"]) == (0.002, 4, 2)
    assert list(res["rows"]) == ROWS and all(list(per) == ["1", "3"] for per in res["rows"].values())
    for name, per in res["rows"].items():
        for worlds, (fwd, bwd) in per.items():
            assert math.isfinite(fwd) and fwd > 0, (name, worlds)
            # differentiable rows time forward + backward too; Featherstone's only up to --slow-max-worlds
            if name.startswith("replay") or (name == "featherstone" and worlds == "1"):
                assert math.isfinite(bwd) and bwd > 0, (name, worlds)
            else:
                assert bwd is None, (name, worlds)
    # the printed table states the same figures, and the ratios of the replay rows to the two references
    table = text[text.index("| solver |"):]
    for name, per in res["rows"].items():
        cells = " | ".join(f"{_fmt(per[w][0])} | {_fmt(per[w][1])}" for w in ("1", "3"))
        assert f"| {name} | {cells} |" in table, table
    ratio = r"\d+\.\dx"
    for row in ("replay rollout / featherstone", "replay step / featherstone"):  # world 3: Featherstone fwd only
        assert re.search(rf"^\| {row} \| {ratio} \| {ratio} \| {ratio} \| n/a \|$", table, re.M), table
    for row in ("replay rollout / mujoco-c", "replay step / mujoco-c"):  # MuJoCo C has no fwd+bwd
        assert re.search(rf"^\| {row} \| {ratio} \| n/a \| {ratio} \| n/a \|$", table, re.M), table
    # the replay rows name the kernels they timed: on the CPU one thread per world, the adjoint as one kernel
    assert res["replay"] == {"lanes": False, "block_dim": None, "threads_per_world": "one thread per world"}
    assert res["adjoint"] == {f"{r} {w}": "one kernel" for r in ("replay rollout", "replay step") for w in (1, 3)}
    assert "SolverReplay as the fits build it: one thread per world; adjoint (auto): replay rollout at 1: one kernel" \
        in text


def test_bench_times_the_adjoint_in_pieces_when_asked_and_says_so(tmp_path, capsys):
    out = tmp_path / "bench.json"
    assert main(["bench", "--robot", "newton:cartpole.urdf", "--gains", "examples/gains/cartpole.toml",
                 "--solvers", "replay", "--worlds", "2", "--steps", "4", "--horizon", "2", "--threads", "1",
                 "--min-time", "0.01", "--adjoint", "pieces", "--json", str(out)]) == 0
    text = capsys.readouterr().out
    forms = json.loads(out.read_text())["adjoint"]
    assert set(forms) == {"replay rollout 2", "replay step 2"}
    assert all(re.fullmatch(r"\d+ kernels of ~400 statements", f) for f in forms.values()), forms
    assert f"(adjoint: {forms['replay step 2']})" in text
