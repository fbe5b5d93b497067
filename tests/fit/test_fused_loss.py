"""The fused path's window loss (:class:`wresdyn.fit.fused_loss.FusedWindowLoss`, two Warp kernels) against
:func:`wresdyn.fit.gradfit.window_loss` through torch's autograd: the loss, its four parts and the gradients of q, q̇
and the actions agree to float32 rounding (the sums run in another order), with and without a torque scale and joint
weights, at one step (no action rate) and at many; the recorded start gets no gradient."""

import pytest
import torch

from wresdyn.fit.fused_loss import FusedWindowLoss
from wresdyn.fit.gradfit import GradFitConfig, window_loss


def _case(b, h, n, seed):
    gen = torch.Generator().manual_seed(seed)
    q, qd = (torch.randn(b, h + 1, n, generator=gen, requires_grad=True) for _ in range(2))
    a = torch.randn(b, h, n, generator=gen, requires_grad=True)
    q_ref, qd_ref = torch.randn(b, h + 1, n, generator=gen), torch.randn(b, h + 1, n, generator=gen)
    return q, qd, a, q_ref, qd_ref, 50.0 * torch.rand(n, generator=gen), torch.rand(n, generator=gen)


def _grads(loss, inputs):
    got = torch.autograd.grad(loss, inputs, allow_unused=True)
    return [torch.zeros_like(x) if g is None else g for g, x in zip(got, inputs)]


@pytest.mark.parametrize("b,h,n,torque,weighted", [(5, 7, 3, True, True), (4, 1, 2, False, False),
                                                   (3, 16, 21, True, False), (2, 9, 4, False, True)])
def test_fused_loss_is_window_loss(b, h, n, torque, weighted):
    cfg = GradFitConfig()
    q, qd, a, q_ref, qd_ref, scale, w = _case(b, h, n, seed=h)
    scale, w = (scale if torque else None), (w if weighted else None)
    ref, ref_parts = window_loss(cfg, q[:, 1:], qd[:, 1:], a, q_ref[:, 1:], qd_ref[:, 1:], scale, w)
    loss, parts = FusedWindowLoss(cfg)(q, qd, a, q_ref, qd_ref, scale, w)
    assert float(loss.detach()) == pytest.approx(float(ref.detach()), rel=2e-6)
    assert set(parts) == set(ref_parts)
    for k in parts:
        assert not parts[k].requires_grad
        assert float(parts[k]) == pytest.approx(float(ref_parts[k]), rel=2e-6, abs=1e-12), k
    expect, got = _grads(ref, (q, qd, a)), _grads(loss, (q, qd, a))
    for e, g in zip(expect, got):
        torch.testing.assert_close(g, e, rtol=2e-5, atol=1e-6 * float(e.abs().max()))
    assert torch.all(got[0][:, 0] == 0) and torch.all(got[1][:, 0] == 0)  # the recorded start
    if not torque and h > 1:  # the action rate alone reaches the actions
        assert got[2].abs().max() > 0


def test_fused_loss_scales_with_the_incoming_gradient():
    cfg = GradFitConfig()
    q, qd, a, q_ref, qd_ref, scale, w = _case(3, 5, 4, seed=0)
    fused = FusedWindowLoss(cfg)
    once = _grads(fused(q, qd, a, q_ref, qd_ref, scale, w)[0], (q, qd, a))
    thrice = _grads(3.0 * fused(q, qd, a, q_ref, qd_ref, scale, w)[0], (q, qd, a))
    for x, y in zip(once, thrice):
        torch.testing.assert_close(y, 3.0 * x)
