"""``benchmarks/speed/gradfit_2000.py``: the whole fixed schedule of the gradient fit run and timed at a tiny size on
the CPU (every iteration run, per-length rates from exact rows, the end's loss and validation), the rows a deferred
(CUDA-graph) fit's wall-clock is exact at, and (CUDA only) the graph-replayed fit against the eager one through it."""

import importlib.util
from pathlib import Path

import pytest
import torch

from wresdyn.fit.gradfit import GradFitConfig
from wresdyn.learn.residual import ResidualConfig

ROOT = Path(__file__).resolve().parents[2]


def _script():
    spec = importlib.util.spec_from_file_location("gradfit_2000", ROOT / "benchmarks/speed/gradfit_2000.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


TINY = GradFitConfig(residual=ResidualConfig(fraction=0.25, hidden_dims=(16, 16)), windows=4,
                     horizon_curriculum=(2, 4), iterations=10, select_every=5, device="cpu")


def test_tiny_cpu_run_times_every_iteration_and_repeats_bit_for_bit(robot, data):
    measure = _script().measure
    a = measure(robot, data, TINY, log=lambda *_: None)
    assert a["iterations"] == 10 and not a["cuda_graph"]
    assert [(x["horizon"], x["iterations"]) for x in a["per_length"]] == [(2, 5), (4, 5)]
    # rates over each length's iterations after its first two (rows 3-5 and 8-10), all positive
    assert [x["measured_over"] for x in a["per_length"]] == [[3, 5], [8, 10]]
    assert all(x["ms_per_iteration"] > 0 for x in a["per_length"])
    rated = sum(x["iterations"] * x["ms_per_iteration"] / 1e3 for x in a["per_length"])
    assert a["overhead_s"] == pytest.approx(a["train_s"] - rated)
    assert a["final_validation"] is not None and a["best_validation"] <= a["final_validation"]
    assert a["best_iteration"] in (5, 10) and a["sim_steps"] == 2 * 4 * (5 * 2 + 5 * 4)
    # the CPU fit is deterministic: a second run gives the same loss, validation and weights, bit for bit
    b = measure(robot, data, TINY, log=lambda *_: None)
    for key in ("final_loss", "final_validation", "best_validation", "returned_params_abs_sum"):
        assert a[key] == b[key], key


def test_deferred_fit_is_timed_only_at_rows_that_waited_for_the_device():
    script = _script()
    cfg = GradFitConfig(iterations=200, horizon_curriculum=(2, 4), select_every=30)
    curve = [{"iteration": i, "wall": 0.01 * i} for i in range(1, 201)]
    # the first two, every 200 // 20 = 10th (log), every 30th (validation) and the last
    expect = sorted({1, 2, 200} | set(range(10, 201, 10)) | set(range(30, 201, 30)))
    assert [r["iteration"] for r in script.exact_rows(curve, cfg, deferred=True)] == expect
    assert len(script.exact_rows(curve, cfg, deferred=False)) == 200
    lengths = script.per_length(curve, cfg, deferred=True)
    assert [x["measured_over"] for x in lengths] == [[10, 100], [110, 200]]
    assert [x["ms_per_iteration"] for x in lengths] == pytest.approx([10.0, 10.0])


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a GPU")
def test_graph_replayed_schedule_gives_the_eager_result(robot, data):
    import dataclasses

    measure = _script().measure
    cfg = dataclasses.replace(TINY, windows=64, iterations=12, select_every=6, device="cuda:0")
    graph = measure(robot, data, cfg, log=lambda *_: None)
    eager = measure(robot, data, dataclasses.replace(cfg, cuda_graph=False), log=lambda *_: None)
    assert graph["cuda_graph"] and not eager["cuda_graph"]
    assert graph["final_loss"] == pytest.approx(eager["final_loss"], rel=1e-3)
    assert graph["final_validation"] == pytest.approx(eager["final_validation"], abs=1e-5)
    assert graph["returned_params_abs_sum"] == pytest.approx(eager["returned_params_abs_sum"], rel=1e-4)


def test_all_worlds_policy_and_unit_gain_give_the_sliced_and_scaled_results_bit_for_bit(robot, data):
    # the fit's per-step savings (no full slice of the state for the policy, no product with a gain of 1) against the
    # longer forms they replace: the same rollout, loss and parameter gradients on the CPU, bit for bit
    import numpy as np

    from wresdyn.fit.gradfit import build_policy
    from wresdyn.learn.residual import obs_stats
    from wresdyn.sim import Simulator, TrajectoryBank, rollout

    train = data.split("train")
    torch.manual_seed(0)
    policy = build_policy(robot, TINY.residual, *obs_stats(train))
    sim = Simulator(robot, 4, 1.0 / data.rate_hz, requires_grad=True)
    window = TrajectoryBank(train, sim.device).sample(np.random.default_rng(3), 4, 6)
    noise = torch.randn(6, 4, 4 * robot.n_dof, generator=torch.Generator().manual_seed(1))

    def run(worlds, product=False):
        policy.zero_grad()
        if product:  # the product with the gain of 1 that the unit-gain path skips, written out
            policy._to_residual = lambda a: (1.0 * a).clamp(-1.0, 1.0) * policy.scale
        out = rollout(sim, window, policy, grad=True, truncation=4, obs_noise=0.1, noise=noise, policy_worlds=worlds)
        policy.__dict__.pop("_to_residual", None)
        loss = ((out.q - window.q) ** 2).sum() + (out.actions ** 2).sum()
        loss.backward()
        return [out.q.detach(), out.qd.detach(), out.actions.detach(), *(p.grad.clone() for p in policy.parameters())]

    fast, sliced, scaled = run(None), run(slice(None)), run(None, product=True)
    assert policy.gain == 1.0 and "_to_residual" not in policy.__dict__ and len(fast) > 3
    for a, b, c in zip(fast, sliced, scaled):
        assert torch.equal(a, b) and torch.equal(a, c)
