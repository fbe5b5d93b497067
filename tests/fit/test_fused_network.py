"""``GradFitConfig.fused_network`` on a tiny CPU fit: the same losses, validation and selection as the plain path to
float32 rounding (the parameters' gradients are the same sums in another order, and Adam is torch's fused kernel;
over a few iterations that moves the loss by ~1e-7 relative: checked at 1e-5), refused for networks it does not run,
and a plain run's checkpoint resumed with it."""

import dataclasses

import pytest
import torch

from wresdyn.errors import WresdynError
from wresdyn.fit.gradfit import GradFitConfig, fit
from wresdyn.learn.residual import ResidualConfig

TINY = GradFitConfig(residual=ResidualConfig(fraction=0.25, hidden_dims=(32, 32)), windows=4,
                     horizon_curriculum=(2, 4, 8), iterations=9, select_every=3)


def _figures(policy, curve):
    checks = [(r["iteration"], r["validation"]) for r in curve if "validation" in r]
    best = min(checks, key=lambda c: c[1])
    params = torch.cat([p.detach().flatten() for p in policy.parameters()])
    return [r["loss"] for r in curve], checks, best[0], params


def test_fused_fit_gives_the_plain_fit(robot, data):
    plain = _figures(*fit(robot, data, TINY, log=lambda *_: None))
    fused = _figures(*fit(robot, data, dataclasses.replace(TINY, fused_network=True), log=lambda *_: None))
    assert fused[0] == pytest.approx(plain[0], rel=1e-5)
    assert [c[0] for c in fused[1]] == [c[0] for c in plain[1]]
    assert [c[1] for c in fused[1]] == pytest.approx([c[1] for c in plain[1]], abs=1e-6)  # [rad]
    assert fused[2] == plain[2]  # the same residual selected
    torch.testing.assert_close(fused[3], plain[3], rtol=1e-4, atol=1e-6)


def test_fused_network_runs_the_mlp_only():
    with pytest.raises(WresdynError, match="MLP network only"):
        dataclasses.replace(TINY, fused_network=True, residual=ResidualConfig(arch="gru"))
    with pytest.raises(WresdynError, match="MLP network only"):
        dataclasses.replace(TINY, fused_network=True, model="parametric")


def test_network_paths_run_the_tiles_on_cuda_by_default():
    assert TINY.network_paths() == (False, False)  # the CPU: the plain path, whose results stay bit for bit
    cuda = dataclasses.replace(TINY, device="cuda:0")
    assert cuda.network_paths() == (True, True)
    assert cuda.network_paths(fusable=False) == (False, False)  # a residual the fused path cannot run
    assert dataclasses.replace(cuda, residual=ResidualConfig(arch="gru")).network_paths() == (False, False)
    assert dataclasses.replace(cuda, model="parametric").network_paths() == (False, False)
    assert dataclasses.replace(cuda, network_tiles=False).network_paths() == (True, False)
    assert dataclasses.replace(cuda, fused_network=False).network_paths() == (False, False)
    assert dataclasses.replace(TINY, fused_network=True).network_paths() == (True, False)
    assert dataclasses.replace(TINY, network_tiles=True).network_paths() == (True, True)  # tiles imply the fused path
    with pytest.raises(WresdynError, match="MLP network only"):
        dataclasses.replace(cuda, network_tiles=True, model="parametric")


def test_plain_checkpoint_resumes_fused(robot, data, tmp_path):
    fit(robot, data, TINY, out=tmp_path, until=4, log=lambda *_: None)
    _, curve = fit(robot, data, dataclasses.replace(TINY, fused_network=True), out=tmp_path, log=lambda *_: None)
    assert [r["iteration"] for r in curve] == list(range(1, 10))
    assert all(torch.isfinite(torch.tensor(r["loss"])) for r in curve)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a GPU")
def test_graph_replayed_fused_fit_gives_the_eager_plain_fit(robot, data):
    # the fused step, its deferred gradients and fused Adam inside the CUDA graph against the plain path run eagerly:
    # the bounds of the graph-against-eager test of the plain path (tests/learn/test_gradfit_2000.py)
    cfg = dataclasses.replace(TINY, windows=64, iterations=12, select_every=6, device="cuda:0", fused_network=False,
                              network_tiles=False)  # the plain path, which CUDA runs only when told
    fused = _figures(*fit(robot, data, dataclasses.replace(cfg, fused_network=True), log=lambda *_: None))
    plain = _figures(*fit(robot, data, dataclasses.replace(cfg, cuda_graph=False), log=lambda *_: None))
    assert fused[0][-1] == pytest.approx(plain[0][-1], rel=1e-3)
    assert fused[1][-1][1] == pytest.approx(plain[1][-1][1], abs=1e-5)
    torch.testing.assert_close(fused[3].cpu(), plain[3].cpu(), rtol=1e-3, atol=1e-5)
