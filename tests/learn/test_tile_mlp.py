""":class:`wresdyn.learn.fused_mlp.FusedMLPRollout` with ``tiles=True`` (each step's network forward and backward as one
Warp tile kernel each, :mod:`wresdyn.learn.tile_mlp`) against its torch operations, on the CPU and, where there is one,
a GPU. The kernels sum each GEMM in another order, so the two agree to float32 rounding, not bit for bit: every buffer,
residual and gradient within 1e-5 of its largest entry. Measured on the CPU (``benchmarks/results/speed/tiles_cpu/``):
up to 2.3e-6 on one step, whose outputs go far past the clip (the pre-clip sums' rounding, relative to the larger sums),
7e-7 after the chain of steps; a wrong term or a missed mask entry would show at 1e-3 or more. The buffers are checked
directly on one step (the clip's mask, the gradient variants the rollout hands back: the residual's, the action's,
both, none), on the chain of ``tests/learn/test_fused_mlp.py`` and on a short gradient fit."""

import dataclasses

import pytest
import torch

from wresdyn.fit.gradfit import GradFitConfig, fit
from wresdyn.learn import tile_mlp
from wresdyn.learn.fused_mlp import FusedMLPRollout
from wresdyn.learn.residual import EluMLP, MLPResidualPolicy, ResidualConfig
from wresdyn.learn.tile_mlp import ENV_BLOCK, TileBlock

# the humanoid's 21 joints, its 4n observation; hidden widths of TINY's network below (one shape, one compile)
N, HIDDEN, H = 21, (32, 32), 6
DEVICES = ["cpu", pytest.param("cuda:0", marks=pytest.mark.skipif(not torch.cuda.is_available(), reason="no GPU"))]
TINY = GradFitConfig(residual=ResidualConfig(fraction=0.25, hidden_dims=HIDDEN), windows=4,
                     horizon_curriculum=(2, 4, 8), iterations=9, select_every=3)


def _policy(device, hidden=HIDDEN, n=N):
    torch.manual_seed(0)
    mlp = EluMLP(4 * n, n, list(hidden))
    # observations spread past the normaliser, and an output large enough that the clip cuts some entries
    return MLPResidualPolicy(mlp, torch.randn(4 * n) * 0.1, torch.rand(4 * n) + 0.5, torch.rand(n) + 0.5,
                             "torque").to(device)


def _close(a, b, rtol=1e-5):
    torch.testing.assert_close(a, b, rtol=rtol, atol=rtol * b.abs().max().item())


def _chain(tiles: bool, device, batch: int, both: bool):
    policy = _policy(device)
    net = FusedMLPRollout(policy, tiles=tiles)
    net.begin(H, batch)
    net.reset()
    g = torch.Generator().manual_seed(1)
    s0 = (torch.randn(batch, N, generator=g) * 3).to(device).requires_grad_()
    mix = (torch.randn(4 * N, N, generator=g) * 0.1).to(device)
    s, outs, acts = s0, [], []
    for k in range(H):
        if k == 3:  # truncation: the observations after it carry no gradient to the start
            s = s.detach()
        cmd = torch.randn(batch, N, generator=g).to(device)
        obs = torch.cat([s, 2 * s, s.sin(), cmd], -1) * 2 if k else torch.cat([s0.detach()] * 3 + [cmd], -1)
        r, a = net.residual_and_action(obs) if both else (net(obs), None)
        outs.append(r)
        acts.append(r / policy.scale if a is None else a)
        s = s + 0.1 * r + 0.05 * (obs @ mix)
    residuals = torch.stack(outs, 1)
    ((s ** 2).sum() + (torch.stack(acts, 1) ** 2).sum()).backward()
    net.finish()
    return residuals.detach(), s0.grad, {k: p.grad.clone() for k, p in policy.named_parameters()}, policy.scale


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("batch, both", [(8, False), (8, True), (37, True)])  # 37: full blocks and a part
def test_tile_chain_gives_the_torch_chain(device, batch, both):
    ref, tile = _chain(False, device, batch, both), _chain(True, device, batch, both)
    assert ((ref[0].abs() - ref[3]).abs() < 1e-6).any(), "the clip never cut: the test misses its mask"
    _close(tile[0], ref[0])
    _close(tile[1], ref[1])
    assert tile[2].keys() == ref[2].keys()
    for name, g in ref[2].items():
        _close(tile[2][name], g)


@torch.no_grad()  # as inside the step's autograd node
def _one_step(tiles: bool, policy, obs, g_r, g_a, need_obs: bool):
    net = FusedMLPRollout(policy, tiles=tiles)
    net.begin(2, obs.shape[0])
    r = net._forward(obs, 1, None, True)[0]
    g_obs = net._backward(g_r, g_a, 1, need_obs)
    return r, g_obs, [t[1] for t in net._x], [t[1] for t in net._z], [t[1] for t in net._g], net._mask[1]


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("hidden, batch", [(HIDDEN, 19), ((256, 128, 64), 64)])  # the second: the fit's network
def test_one_step_writes_the_torch_buffers(device, hidden, batch):
    policy = _policy(device, hidden)
    policy.mlp[-1].weight.data.mul_(10)  # outputs past the clip at the fit's network's initial weights too
    g = torch.Generator().manual_seed(2)
    obs = (torch.randn(batch, 4 * N, generator=g) * 4).to(device)
    grads = [(torch.randn(batch, N, generator=g)).to(device) for _ in range(2)]
    cases = [(grads[0], grads[1], True), (grads[0], None, False), (None, grads[1], True), (None, None, True)]
    for g_r, g_a, need_obs in cases:
        ref, tile = (_one_step(tiles, policy, obs, g_r, g_a, need_obs) for tiles in (False, True))
        assert 0 < int(ref[5].sum()) < ref[5].numel(), "the clip cuts some entries and passes others"
        assert torch.equal(tile[5], ref[5])
        _close(tile[0], ref[0])
        assert (tile[1] is None) == (not need_obs)
        if need_obs:
            _close(tile[1], ref[1])
        for a, b in zip(tile[2] + tile[3] + tile[4], ref[2] + ref[3] + ref[4], strict=True):
            _close(a, b)
        if g_r is None and g_a is None:
            assert not tile[4][-1].any()


@pytest.mark.parametrize("device", DEVICES)
def test_strided_inputs_give_the_torch_buffers(device):
    # autograd hands gradients expanded (stride 0) or transposed, a rollout may hand a strided observation: the
    # kernels read them through their strides
    policy = _policy(device)
    policy.mlp[-1].weight.data.mul_(10)
    g = torch.Generator().manual_seed(3)
    obs = (torch.randn(19, 8 * N, generator=g) * 4).to(device)[:, ::2]
    g_r = torch.randn(1, N, generator=g).to(device).expand(19, N)
    g_a = torch.randn(N, 19, generator=g).to(device).t()
    ref, tile = (_one_step(tiles, policy, obs, g_r, g_a, True) for tiles in (False, True))
    assert torch.equal(tile[5], ref[5])
    for a, b in zip([tile[0], tile[1]] + tile[2] + tile[3] + tile[4], [ref[0], ref[1]] + ref[2] + ref[3] + ref[4],
                    strict=True):
        _close(a, b)


def _figures(policy, curve):
    checks = [(r["iteration"], r["validation"]) for r in curve if "validation" in r]
    params = torch.cat([p.detach().flatten() for p in policy.parameters()])
    return [r["loss"] for r in curve], checks, params


def test_tile_fit_gives_the_fused_fit(robot, data):
    # the fused fit's own bound against the plain one (tests/fit/test_fused_network.py): ~1e-7 relative measured
    fused = _figures(*fit(robot, data, dataclasses.replace(TINY, fused_network=True), log=lambda *_: None))
    tiles = _figures(*fit(robot, data, dataclasses.replace(TINY, fused_network=True, network_tiles=True),
                          log=lambda *_: None))
    assert tiles[0] == pytest.approx(fused[0], rel=1e-5)
    assert [c[0] for c in tiles[1]] == [c[0] for c in fused[1]]
    assert [c[1] for c in tiles[1]] == pytest.approx([c[1] for c in fused[1]], abs=1e-6)  # [rad]
    torch.testing.assert_close(tiles[2], fused[2], rtol=1e-4, atol=1e-6)


def test_fused_checkpoint_resumes_with_tiles(robot, data, tmp_path):
    # network_tiles changes only the rounding: a resumed fit may switch it on (RESUME_MAY_CHANGE)
    fused = dataclasses.replace(TINY, fused_network=True)
    fit(robot, data, fused, out=tmp_path, until=4, log=lambda *_: None)
    _, curve = fit(robot, data, dataclasses.replace(fused, network_tiles=True), out=tmp_path, log=lambda *_: None)
    assert [r["iteration"] for r in curve] == list(range(1, 10))
    assert all(torch.isfinite(torch.tensor(r["loss"])) for r in curve)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="CUDA graphs need a GPU")
def test_graph_replayed_tile_fit_gives_the_graph_replayed_fused_fit(robot, data):
    # the tile kernels launched on torch's stream inside the captured iteration: the bounds of the graph-against-eager
    # test of the fused path (tests/fit/test_fused_network.py)
    cfg = dataclasses.replace(TINY, windows=64, iterations=12, select_every=6, device="cuda:0", fused_network=True,
                              network_tiles=False)
    fused = _figures(*fit(robot, data, cfg, log=lambda *_: None))
    tiles = _figures(*fit(robot, data, dataclasses.replace(cfg, network_tiles=True), log=lambda *_: None))
    assert tiles[0][-1] == pytest.approx(fused[0][-1], rel=1e-3)
    assert tiles[1][-1][1] == pytest.approx(fused[1][-1][1], abs=1e-5)
    torch.testing.assert_close(tiles[2].cpu(), fused[2].cpu(), rtol=1e-3, atol=1e-5)


def test_tiles_need_the_fused_network():
    from wresdyn.errors import WresdynError

    with pytest.raises(WresdynError, match="set fused_network too"):
        dataclasses.replace(TINY, fused_network=False, network_tiles=True)


def test_tile_block_parses_rows_chunk_threads_and_mathdx():
    assert TileBlock.parse("16x32x128m") == TileBlock(16, 32, 128, True)
    assert TileBlock.parse(" 8x64x256 ") == TileBlock(8, 64, 256, False)
    for bad in ("16x32", "16x32x128M", "16x32x0", "a6x32x128", "16x32x128mm", ""):
        with pytest.raises(ValueError, match="ROWSxCHUNKxTHREADS"):
            TileBlock.parse(bad)


def test_tile_block_from_env(monkeypatch):
    monkeypatch.delenv(ENV_BLOCK, raising=False)
    assert TileBlock.from_env() == TileBlock() == TileBlock(8, 32, 256, False)
    monkeypatch.setenv(ENV_BLOCK, "32x32x256m")
    assert TileBlock.from_env() == TileBlock(32, 32, 256, True)
    monkeypatch.setenv(ENV_BLOCK, "16x32")
    with pytest.raises(ValueError, match=f"^{ENV_BLOCK}: '16x32' is not") as err:
        TileBlock.from_env()
    assert "\n" not in str(err.value)


def test_env_block_reaches_the_kernels(monkeypatch):
    # TileMLP's default block is the variable's: the kernels' cache key (rows, chunk, MathDx) and the launch's threads;
    # building the kernels compiles nothing (that happens on the first launch)
    monkeypatch.setenv(ENV_BLOCK, "8x16x64m")
    net = FusedMLPRollout(_policy("cpu"), tiles=True)
    dims = (4 * N, *HIDDEN, N)
    assert (net._tiles.rows, net._tiles.threads) == (8, 64)
    assert (net._tiles.forward_kernel, net._tiles.backward_kernel) == tile_mlp._KERNELS[(dims, 1.0, 8, 16, True)]
    assert net._tiles.forward_kernel.module.options["enable_mathdx_gemm"] is True
    monkeypatch.setenv(ENV_BLOCK, "")
    assert FusedMLPRollout(_policy("cpu"), tiles=True)._tiles.forward_kernel == \
        tile_mlp._KERNELS[(dims, 1.0, 8, 32, False)][0]
