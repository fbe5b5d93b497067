""":class:`wresdyn.learn.fused_mlp.FusedMLPRollout` against the plain MLP residual under torch's autograd, at a small
size on the CPU: a chain of steps whose observations depend on the earlier residuals (with a detach, as the fit's
truncation makes, and a first step whose observation carries no gradient). The residuals and the gradient reaching the
chain's start are the plain path's operations on the same values, so equal bit for bit; the parameters' gradients are
the same sums in another order (one GEMM over all steps' rows), equal to the rounding of their dtype: 1e-12 relative in
float64 (a wrong term would show at 1e-3 or more), 1e-5 in float32 (gradients summed over 6 steps of 8 rows: a few
float32 ulps, 1.2e-7 each, times the largest entries)."""

import pytest
import torch

from wresdyn.learn import fused_mlp
from wresdyn.learn.fused_mlp import FusedMLPRollout, fusable
from wresdyn.learn.residual import EluMLP, GRUResidualPolicy, MLPResidualPolicy

N, B, H = 5, 8, 6


def _policy(dtype, gain=1.0):
    torch.manual_seed(0)
    mlp = EluMLP(4 * N, N, [32, 16, 8]).to(dtype)
    # observations spread past the normaliser, and an output large enough that the clip cuts some entries
    return MLPResidualPolicy(mlp, torch.randn(4 * N) * 0.1, torch.rand(4 * N) + 0.5, torch.rand(N) + 0.5, "torque",
                             gain=gain).to(dtype)


def _chain(policy, fused: bool, dtype, into=None, both=False):
    """``both``: the residual and the action from ``residual_and_action`` (the residual written into ``into``'s
    tensors where given), else the action r / scale by autograd."""
    net = policy
    if fused:
        net = FusedMLPRollout(policy)
        net.begin(H, B)
    net.reset()
    g = torch.Generator().manual_seed(1)
    s0 = (torch.randn(B, N, generator=g, dtype=dtype) * 3).requires_grad_()
    mix = torch.randn(4 * N, N, generator=g, dtype=dtype) * 0.5
    s, outs, acts = s0, [], []
    for k in range(H):
        if k == 3:  # truncation: the observations after it carry no gradient to the start
            s = s.detach()
        cmd = torch.randn(B, N, generator=g, dtype=dtype)
        obs = torch.cat([s, 2 * s, s.sin(), cmd], -1) * 2 if k else torch.cat([s0.detach()] * 3 + [cmd], -1)
        r, a = net.residual_and_action(obs, None if into is None else into[k]) if both else (net(obs), None)
        outs.append(r)
        acts.append(r / policy.scale if a is None else a)
        s = s + 0.1 * r + 0.05 * (obs @ mix)
    actions = torch.stack(outs, 1)
    loss = (s ** 2).sum() + (torch.stack(acts, 1) ** 2).sum()
    loss.backward()
    if fused:
        net.finish()
    return actions.detach(), s0.grad, {k: p.grad.clone() for k, p in policy.named_parameters()}


@pytest.mark.parametrize("split", [False, True])  # the weights' gradients as one product over all rows, or per step
@pytest.mark.parametrize("dtype, rtol", [(torch.float64, 1e-12), (torch.float32, 1e-5)])
def test_fused_steps_give_the_plain_values_and_gradients(dtype, rtol, split, monkeypatch):
    monkeypatch.setattr(fused_mlp, "SPLIT_ROWS", H * B if split else H * B + 1)
    plain, fused = _chain(_policy(dtype), False, dtype), _chain(_policy(dtype), True, dtype)
    assert ((plain[0].abs() - _policy(dtype).scale).abs() < 1e-6).any(), "the clip never cut: the test misses its mask"
    assert torch.equal(plain[0], fused[0])
    assert torch.equal(plain[1], fused[1])
    assert plain[2].keys() == fused[2].keys()
    for name, g in plain[2].items():
        torch.testing.assert_close(fused[2][name], g, rtol=rtol, atol=rtol * g.abs().max().item(), msg=name)


@pytest.mark.parametrize("fused", [False, True])
def test_residuals_written_into_given_tensors_give_the_same_results_bit_for_bit(fused):
    # a differentiable rollout hands the simulator's joint-torque inputs (step_forces): the residuals land there, the
    # values and gradients are those without them
    into = [torch.full((B, N), float("nan"), dtype=torch.float32) for _ in range(H)]
    plain, written = _chain(_policy(torch.float32), fused, torch.float32, both=True), \
        _chain(_policy(torch.float32), fused, torch.float32, into, both=True)
    assert torch.equal(plain[0], written[0]) and torch.equal(plain[1], written[1])
    assert all(torch.equal(plain[2][k], written[2][k]) for k in plain[2])
    assert torch.equal(torch.stack(into, 1), written[0])


@pytest.mark.parametrize("fused", [False, True])
def test_residual_and_action_in_one_node_give_the_two_nodes_results_bit_for_bit(fused):
    # the rollout takes (r, r / scale) from one node (ClipScale, the fused step) whose backward sums the two gradients
    # in one addcdiv: the values, the gradient at the chain's start and the parameters' gradients are autograd's
    two, one = (_chain(_policy(torch.float32), fused, torch.float32, both=both) for both in (False, True))
    assert torch.equal(two[0], one[0]) and torch.equal(two[1], one[1])
    assert all(torch.equal(two[2][k], one[2][k]) for k in two[2])


def test_finish_adds_to_existing_gradients_as_autograd_does():
    policy = _policy(torch.float64)
    _chain(policy, True, torch.float64)
    once = {k: p.grad.clone() for k, p in policy.named_parameters()}
    _chain(policy, True, torch.float64)  # no zero_grad in between: the second adds to the first
    for k, p in policy.named_parameters():
        torch.testing.assert_close(p.grad, 2 * once[k], rtol=1e-12, atol=0)


def test_what_is_refused():
    gru = GRUResidualPolicy(torch.nn.GRU(4 * N, 8), EluMLP(8, N, [8]), torch.zeros(4 * N), torch.ones(4 * N),
                            torch.ones(N), "torque")
    assert "not an MLP" in fusable(gru)
    assert "gain 1" in fusable(_policy(torch.float32, gain=0.2))
    with pytest.raises(ValueError, match="cannot fuse"):
        FusedMLPRollout(gru)
    net = FusedMLPRollout(_policy(torch.float32))
    with pytest.raises(RuntimeError, match="begin"):
        net(torch.zeros(B, 4 * N))
    net.begin(2, B)
    net(torch.zeros(B, 4 * N))
    with pytest.raises(RuntimeError, match="after 1 of 2 steps"):
        net.finish()
