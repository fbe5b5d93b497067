""":class:`wresdyn.learn.residual.MaskedClip`, the residual's clip in training with gradients (the gradient fit's plain
path), against torch's own clamp it replaces: the same values and gradients bit for bit, on entries inside, on and past
the bounds, ±0, ±inf and NaN; and which calls take it (training with gradients only: evaluation and export keep
torch's clamp)."""

import math

import torch

from wresdyn.learn.residual import EluMLP, MaskedClip, MLPResidualPolicy


def test_masked_clip_gives_the_clamp_values_and_gradients_bit_for_bit():
    g = torch.Generator().manual_seed(0)
    special = torch.tensor([-1.0, 1.0, -0.0, 0.0, math.inf, -math.inf, math.nan, 1.0000001, -0.9999999, 3.0])
    a = torch.cat([torch.randn(300, generator=g) * 1.5, special]).reshape(31, 10)
    grad = torch.randn(31, 10, generator=g)
    grad[0, :3] = torch.tensor([-0.0, math.nan, math.inf])
    outs = []
    for clip in (MaskedClip.apply, lambda x: x.clamp(-1.0, 1.0)):
        x = a.clone().requires_grad_()
        y = clip(x)
        y.backward(grad)
        outs.append((y.detach(), x.grad))
    (y1, g1), (y2, g2) = outs
    assert (y2.abs() < 1).any() and (a.abs() > 1).any()  # both sides of the bounds are in the test
    for u, v in ((y1, y2), (g1, g2)):
        assert torch.equal(u.isnan(), v.isnan())
        assert torch.equal(torch.nan_to_num(u).view(torch.int32), torch.nan_to_num(v).view(torch.int32))  # ±0 too


def test_only_training_with_gradients_takes_the_masked_clip():
    torch.manual_seed(0)
    policy = MLPResidualPolicy(EluMLP(8, 2, [4]), torch.zeros(8), torch.ones(8), torch.ones(2), "torque")
    obs = torch.randn(3, 8) * 50
    assert type(policy(obs).grad_fn).__name__ == "MulBackward0"
    assert type(policy(obs).grad_fn.next_functions[0][0]).__name__ == "MaskedClipBackward"
    policy.eval()
    assert type(policy(obs).grad_fn.next_functions[0][0]).__name__ == "ClampBackward1"
    with torch.no_grad():
        assert policy.train()(obs).grad_fn is None
