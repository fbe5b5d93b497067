"""The gradient fit's window loss (:func:`wresdyn.fit.gradfit.window_loss`) as two Warp kernels, for the fused path
(``GradFitConfig.fused_network``).

Through torch the loss and its backward are about forty small kernels an iteration (slices, differences, squares,
weighted sums and means, and the slices' backward filling zeros), whatever the window length; on a GPU each is a few
microseconds of a graph whose iteration at short windows is well under a millisecond. Here one kernel forms each window
and step's four sums over the joints (position and velocity error, residual torque, action rate), torch adds them up
(one reduction, deterministic) and weighs them, and one kernel writes the gradients of the simulated q, q̇ (the whole
(B, H + 1, n) rollout, zero at the recorded start) and of the actions, one thread an element. The same loss to float32
rounding: the sums run over the joints first, then the steps and windows.
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
    # one thread per window b and step k: its four sums over the joints
    b, k = wp.tid()
    pos, vel, tau, rate = float(0.0), float(0.0), float(0.0), float(0.0)
    for j in range(a.shape[2]):
        e = q[b, k + 1, j] - q_ref[b, k + 1, j]
        ev = qd[b, k + 1, j] - qd_ref[b, k + 1, j]
        x = a[b, k, j]
        t = x * scale[j]
        pos += w[j] * (e * e)
        vel += w[j] * (ev * ev)
        tau += t * t
        if k > 0:
            d = x - a[b, k - 1, j]
            rate += d * d
    sums[b, k, 0] = pos
    sums[b, k, 1] = vel
    sums[b, k, 2] = tau
    sums[b, k, 3] = rate


@wp.kernel
def _window_grads(q: wp.array3d(dtype=float), qd: wp.array3d(dtype=float), q_ref: wp.array3d(dtype=float),
                  qd_ref: wp.array3d(dtype=float), a: wp.array3d(dtype=float), scale: wp.array(dtype=float),
                  w: wp.array(dtype=float), coef: wp.array(dtype=float), g_loss: wp.array(dtype=float),
                  g_q: wp.array3d(dtype=float), g_qd: wp.array3d(dtype=float), g_a: wp.array3d(dtype=float)):
    # one thread per window b, sample i (0: the recorded start; i >= 1: the state after step i - 1) and joint j;
    # coef: the loss's weight of each of the four sums (its term's weight over the term's count)
    b, i, j = wp.tid()
    if i == 0:
        g_q[b, 0, j] = 0.0
        g_qd[b, 0, j] = 0.0
        return
    g = 2.0 * g_loss[0]
    g_q[b, i, j] = g * coef[0] * w[j] * (q[b, i, j] - q_ref[b, i, j])
    g_qd[b, i, j] = g * coef[1] * w[j] * (qd[b, i, j] - qd_ref[b, i, j])
    k = i - 1
    steps = a.shape[1]
    x = a[b, k, j]
    d = float(0.0)
    if k > 0:
        d += x - a[b, k - 1, j]
    if k + 1 < steps:
        d -= a[b, k + 1, j] - x
    s = scale[j]
    g_a[b, k, j] = g * (coef[2] * s * s * x + coef[3] * d)


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
        sums = torch.empty(b, h, 4, device=q.device, dtype=torch.float32)
        ins = [_wp(t) for t in (q, qd, q_ref, qd_ref, a, scale, w)]
        wdev = wp.device_from_torch(q.device)
        wp.launch(_window_sums, dim=(b, h), inputs=[*ins, _wp(sums)], device=wdev, stream=owner.stream(q.device))
        total = sums.view(b * h, 4).sum(0)
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
        wp.launch(_window_grads, dim=(b, h + 1, n), inputs=args, device=wp.device_from_torch(q.device),
                  stream=ctx.owner.stream(q.device))
        return g_q, g_qd, g_a, *[None] * 7
