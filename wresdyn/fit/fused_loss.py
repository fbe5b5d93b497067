"""The gradient fit's window loss (:func:`wresdyn.fit.gradfit.window_loss`) as two Warp kernels, for the fused path
(``GradFitConfig.fused_network``).

Through torch the loss and its backward are about forty small kernels an iteration (slices, differences, squares,
weighted sums and means, and the slices' backward filling zeros), whatever the window length; on a GPU each is a few
microseconds of a graph whose iteration at short windows is well under a millisecond. Here one kernel forms each window
and joint's four sums over the steps (position and velocity error, residual torque, action rate), torch adds them up
(one reduction, deterministic) and weighs them, and one kernel writes the gradients of the simulated q, q̇ (the whole
(B, H + 1, n) rollout, zero at the recorded start) and of the actions. The same loss to float32 rounding: the sums run
over the steps first, then the joints and windows.
"""

from __future__ import annotations

import torch
import warp as wp

from ..sim.devices import torch_stream_for_warp

__all__ = ["FusedWindowLoss"]


@wp.kernel
def _window_sums(q: wp.array3d(dtype=float), qd: wp.array3d(dtype=float), q_ref: wp.array3d(dtype=float),
                 qd_ref: wp.array3d(dtype=float), a: wp.array3d(dtype=float), scale: wp.array(dtype=float),
                 w: wp.array(dtype=float), sums: wp.array3d(dtype=float)):
    # one thread per window b and joint j: its sums over the steps, weighted by the joint's fit weight
    b, j = wp.tid()
    steps = a.shape[1]
    s = scale[j]
    pos, vel, tau, rate = float(0.0), float(0.0), float(0.0), float(0.0)
    prev = float(0.0)
    for k in range(steps):
        e = q[b, k + 1, j] - q_ref[b, k + 1, j]
        ev = qd[b, k + 1, j] - qd_ref[b, k + 1, j]
        x = a[b, k, j]
        t = x * s
        pos += e * e
        vel += ev * ev
        tau += t * t
        if k > 0:
            d = x - prev
            rate += d * d
        prev = x
    sums[b, j, 0] = w[j] * pos
    sums[b, j, 1] = w[j] * vel
    sums[b, j, 2] = tau
    sums[b, j, 3] = rate


@wp.kernel
def _window_grads(q: wp.array3d(dtype=float), qd: wp.array3d(dtype=float), q_ref: wp.array3d(dtype=float),
                  qd_ref: wp.array3d(dtype=float), a: wp.array3d(dtype=float), scale: wp.array(dtype=float),
                  w: wp.array(dtype=float), coef: wp.array(dtype=float), g_loss: wp.array(dtype=float),
                  g_q: wp.array3d(dtype=float), g_qd: wp.array3d(dtype=float), g_a: wp.array3d(dtype=float)):
    # coef: the loss's weight of each of the four sums (its term's weight over the term's count)
    b, j = wp.tid()
    steps = a.shape[1]
    g = g_loss[0]
    cq = 2.0 * g * coef[0] * w[j]
    cqd = 2.0 * g * coef[1] * w[j]
    s = scale[j]
    ct = 2.0 * g * coef[2] * s * s
    cr = 2.0 * g * coef[3]
    g_q[b, 0, j] = 0.0
    g_qd[b, 0, j] = 0.0
    for k in range(steps):
        g_q[b, k + 1, j] = cq * (q[b, k + 1, j] - q_ref[b, k + 1, j])
        g_qd[b, k + 1, j] = cqd * (qd[b, k + 1, j] - qd_ref[b, k + 1, j])
        x = a[b, k, j]
        d = float(0.0)
        if k > 0:
            d += x - a[b, k - 1, j]
        if k + 1 < steps:
            d -= a[b, k + 1, j] - x
        g_a[b, k, j] = ct * x + cr * d


def _wp(t: torch.Tensor):
    return wp.from_torch(t, requires_grad=False)


class FusedWindowLoss:
    """:func:`~wresdyn.fit.gradfit.window_loss` of ``cfg``'s weights for windows of one batch: called with the
    rollout's whole q, q̇ (B, H + 1, n) [rad, rad/s], its normalised actions (B, H, n), the window's recorded q, q̇
    (B, H + 1, n), the residual's scale (n,) [N·m] (``None``: a delta action, no torque term) and the joints' fit
    weights (n,) (``None``: all 1); returns (loss, parts) as ``window_loss`` does, the loss differentiable in q, q̇ and
    the actions (a ``torch.autograd.Function``). Float32 tensors on one device; the kernels launch on torch's
    current stream (a CUDA graph torch captures holds them)."""

    def __init__(self, cfg) -> None:
        wp.init()
        self.weights = torch.tensor([cfg.w_q, cfg.w_qd, cfg.w_torque, cfg.w_action_rate], dtype=torch.float64)
        self._streams: dict[int, tuple] = {}
        self._coef: dict[tuple, torch.Tensor] = {}  # per (B, H, device): the four sums' weights in the loss
        self._ones: dict[tuple, torch.Tensor] = {}
        self._zeros: dict[tuple, torch.Tensor] = {}

    def coefficients(self, batch: int, steps: int, device) -> tuple[torch.Tensor, torch.Tensor]:
        """(per-sum mean factors (4,), the loss's weights of the sums (4,)) for B windows of H steps: the means
        over B·H rows (B·(H − 1) differences for the action rate; none at H = 1)."""
        key = (batch, steps, str(device))
        if key not in self._coef:
            rows = batch * steps
            mean = torch.tensor([1.0 / rows] * 3 + [1.0 / (batch * (steps - 1)) if steps > 1 else 0.0],
                                dtype=torch.float64)
            self._coef[key] = torch.stack([mean, mean * self.weights]).to(device, torch.float32)
        c = self._coef[key]
        return c[0], c[1]

    def _fill(self, cache: dict, n: int, device, value: float) -> torch.Tensor:
        key = (n, str(device))
        if key not in cache:  # made by the first (eager) iteration and kept: a captured graph reads it
            cache[key] = torch.full((n,), value, device=device, dtype=torch.float32)
        return cache[key]

    def __call__(self, q, qd, actions, q_ref, qd_ref, scale, weights=None):
        n, dev = q.shape[-1], q.device
        scale = self._fill(self._zeros, n, dev, 0.0) if scale is None else scale
        weights = self._fill(self._ones, n, dev, 1.0) if weights is None else weights
        mean, coef = self.coefficients(actions.shape[0], actions.shape[1], dev)
        loss, parts = _Loss.apply(q, qd, actions, q_ref.contiguous(), qd_ref.contiguous(), scale.contiguous(),
                                  weights.contiguous(), mean, coef, self)
        return loss, dict(zip(("pos", "vel", "torque", "rate"), parts.unbind()))

    def stream(self, device):
        """Torch's current stream as a Warp stream (``None`` on the CPU and torch's default stream)."""
        return torch_stream_for_warp(device, self._streams) if device.type == "cuda" else None


class _Loss(torch.autograd.Function):
    @staticmethod
    def forward(ctx, q, qd, a, q_ref, qd_ref, scale, w, mean, coef, owner):
        b, h, n = a.shape
        q, qd, a = q.contiguous(), qd.contiguous(), a.contiguous()
        sums = torch.empty(b, n, 4, device=q.device, dtype=torch.float32)
        ins = [_wp(t) for t in (q, qd, q_ref, qd_ref, a, scale, w)]
        wdev = wp.device_from_torch(q.device)
        wp.launch(_window_sums, dim=(b, n), inputs=[*ins, _wp(sums)], device=wdev, stream=owner.stream(q.device))
        total = sums.view(b * n, 4).sum(0)
        ctx.save_for_backward(q, qd, a, q_ref, qd_ref, scale, w, coef)
        ctx.owner = owner
        parts = total * mean
        ctx.mark_non_differentiable(parts)
        return torch.dot(total, coef), parts

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_loss, _g_parts):
        q, qd, a, q_ref, qd_ref, scale, w, coef = ctx.saved_tensors
        b, h, n = a.shape
        g_q, g_qd, g_a = torch.empty_like(q), torch.empty_like(qd), torch.empty_like(a)
        g = g_loss.reshape(1).to(torch.float32).contiguous()
        args = [_wp(t) for t in (q, qd, q_ref, qd_ref, a, scale, w, coef, g, g_q, g_qd, g_a)]
        wp.launch(_window_grads, dim=(b, n), inputs=args, device=wp.device_from_torch(q.device),
                  stream=ctx.owner.stream(q.device))
        return g_q, g_qd, g_a, *[None] * 7
