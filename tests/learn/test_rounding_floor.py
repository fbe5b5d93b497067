"""``benchmarks/speed/rounding_floor.py`` at a tiny size on the CPU: the control (stopped after one iteration and
resumed untouched) ends bit for bit where an uninterrupted fit does, and a nudge moves each network weight by exactly
one unit in the last place and the fit's end with it."""

import importlib.util
from pathlib import Path

import torch

from wresdyn.fit.gradfit import GradFitConfig, fit
from wresdyn.learn.residual import ResidualConfig

ROOT = Path(__file__).resolve().parents[2]


def _script():
    spec = importlib.util.spec_from_file_location("rounding_floor", ROOT / "benchmarks/speed/rounding_floor.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


TINY = GradFitConfig(residual=ResidualConfig(fraction=0.25, hidden_dims=(16, 16)), windows=4,
                     horizon_curriculum=(2, 4), iterations=8, select_every=4, device="cpu")


def test_nudge_moves_each_weight_one_unit_in_the_last_place():
    state = {"w": torch.tensor([1.0, -2.0, 0.0, 3.5]), "buffer": torch.tensor([7.0])}
    out = _script().nudge(state, ["w"], seed=3)
    moved = out["w"] != state["w"]
    assert bool(moved.all()) and torch.equal(out["buffer"], state["buffer"])
    for a, b in zip(state["w"].tolist(), out["w"].tolist()):  # the next float32 up or down, nothing between
        lo, hi = sorted((a, b))
        assert torch.nextafter(torch.tensor(lo), torch.tensor(hi)).item() == hi


def test_control_is_the_uninterrupted_fit_and_a_nudge_moves_the_end(robot, data):
    _, curve = fit(robot, data, TINY, log=lambda *_: None)
    result = _script().floor(robot, data, TINY, nudges=[1], at=1)
    assert result["control_final_validation"] == curve[-1]["validation"]  # bit for bit
    nudged = result["nudged"][0]
    assert nudged["iterations"] == TINY.iterations
    assert nudged["returned_params_abs_sum"] != result["control"]["returned_params_abs_sum"]
    assert 0.0 <= nudged["distance_rad"] < 1e-3 and result["floor_rad"] == nudged["distance_rad"]
