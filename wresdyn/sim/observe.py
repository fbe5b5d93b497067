"""The residual policy's observation of one differentiable rollout step as one autograd node: one kernel forward, one
backward.

The observation [q, q̇, q̈, q_cmd] (:func:`~wresdyn.sim.residual_kinds.observation`) of step k, with
q̈_k = (q̇_k − q̇_{k−1}) / dt and the observation noise added, costs a subtraction, a division, a concatenation and an
addition as torch operators, and their backward a division, a negation and the concatenation's slices: on CUDA each
a launch-bound kernel of a few microseconds in a serial chain of such steps. :func:`observe` computes the same
values in one Warp kernel writing the (N, 4n) observation, and its backward the two gradients the difference sends
(+g/dt to q̇_k, −g/dt to q̇_{k−1}) in one more; the slices of q and q̇ are views of the incoming gradient.

The results are those of the torch operators to the last bit: the same IEEE operations in the same order (a true
division on the CPU; on CUDA, where torch divides by a scalar as a product with its float32 reciprocal, that
product), with floating-point contraction off so that the noise is added to the rounded q̈. Autograd adds the
gradients reaching q̇_k in the same order as well: :class:`_Observe` takes q̇_k twice, once for its own slice and once
for the difference, so the engine accumulates the slice and then +g/dt, as it did the concatenation's slice and then
the subtraction's gradient.

:data:`ENV` switches it. On the CPU the node runs the same torch operators inside it by default (a CPU Warp launch
costs ~50 µs of Python, more than the operators it replaces; the node's gradients and their order are the same); on
CUDA it is off unless set to 1, until its bits are checked on a GPU; ``warp`` runs the Warp kernels on the CPU too, to
check their bits there (``tests/sim/test_observe.py``) and to count what a CUDA step launches
(``benchmarks/speed/gradfit_torch_ops.py``).
"""

import functools
import os

import numpy as np
import torch

__all__ = ["ENV", "mode", "observe", "observe_modules"]

ENV = "WRESDYN_OBS_NODE"
"""``1``: the rollout's observation node (:func:`observe`) on every device, the Warp kernels on CUDA and the torch
operators on the CPU; ``warp``: the node with the Warp kernels on every device; ``0``: no node (the torch operators
as autograd records them); unset: no node (on the CPU the node, a Python autograd function, costs 2-3 % of an
iteration, ``benchmarks/results/speed/obsnode_cpu/``; on CUDA it waits for a GPU check of the fits' captured graphs)."""

_streams: dict[int, object] = {}  # torch stream handle -> its Warp stream, made once per stream


def mode(device) -> str | None:
    """How a differentiable rollout on ``device`` builds its observations (:data:`ENV`): ``"warp"`` (:func:`observe`
    with the Warp kernels), ``"torch"`` (:func:`observe` with the torch operators) or ``None`` (no node)."""
    given = os.environ.get(ENV, "").strip()
    cuda = str(device).startswith("cuda")
    if given not in ("1", "warp"):
        return None
    return "warp" if given == "warp" or cuda else "torch"


@functools.cache
def _kernels(dtype: torch.dtype):
    """The forward and backward kernels in the precision of ``dtype`` (float32 or float64)."""
    import warp as wp

    wp.init()
    real = {torch.float32: wp.float32, torch.float64: wp.float64}[dtype]
    # no fused multiply-add: torch rounds q̈ before it adds the noise, in another kernel
    options = {"fuse_fp": False}

    @wp.func
    def rate(a: real, b: real, scale: real, recip: wp.int32):
        if recip != 0:
            return (a - b) * scale
        return (a - b) / scale

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def forward(q_in: wp.array2d(dtype=real), qd_in: wp.array2d(dtype=real), prev_in: wp.array2d(dtype=real),
                cmd_in: wp.array2d(dtype=real), noise_in: wp.array2d(dtype=real), scale: real, recip: wp.int32,
                diff: wp.int32, noisy: wp.int32, obs_out: wp.array2d(dtype=real)):
        i, j = wp.tid()
        n = q_in.shape[1]
        qd = qd_in[i, j]
        qdd = prev_in[i, j]
        if diff != 0:
            qdd = rate(qd, qdd, scale, recip)
        if noisy != 0:
            obs_out[i, j] = q_in[i, j] + noise_in[i, j]
            obs_out[i, n + j] = qd + noise_in[i, n + j]
            obs_out[i, 2 * n + j] = qdd + noise_in[i, 2 * n + j]
            obs_out[i, 3 * n + j] = cmd_in[i, j] + noise_in[i, 3 * n + j]
        else:
            obs_out[i, j] = q_in[i, j]
            obs_out[i, n + j] = qd
            obs_out[i, 2 * n + j] = qdd
            obs_out[i, 3 * n + j] = cmd_in[i, j]

    @wp.kernel(enable_backward=False, module="unique", module_options=options)
    def backward(adj_obs_in: wp.array2d(dtype=real), scale: real, recip: wp.int32, adj_out: wp.array3d(dtype=real)):
        i, j = wp.tid()
        n = adj_out.shape[2]
        g = adj_obs_in[i, 2 * n + j]
        if recip != 0:
            g = g * scale
        else:
            g = g / scale
        adj_out[0, i, j] = g  # q̇_k's, as the subtraction's first operand
        adj_out[1, i, j] = -g  # q̇_{k-1}'s

    return forward, backward


def observe_modules(dtype: torch.dtype = torch.float32) -> list:
    """The Warp modules of :func:`observe`'s kernels, for compiling ahead (:func:`wresdyn.sim.warmup.warm_up`)."""
    return [k.module for k in _kernels(dtype)]


@functools.lru_cache(maxsize=64)
def _scale(dt: float, device: torch.device, dtype: torch.dtype) -> tuple[float, int]:
    """What the kernels divide by (``recip`` 0) or multiply with (``recip`` 1): torch's own operand for a tensor
    divided by the Python float ``dt`` on ``device``. On the CPU torch divides by ``dt`` rounded to the tensor's
    dtype; on CUDA it multiplies by the reciprocal of that, computed in the dtype."""
    np_dtype = np.float32 if dtype == torch.float32 else np.float64
    d = np_dtype(dt)
    return (float(np_dtype(1.0) / d), 1) if device.type == "cuda" else (float(d), 0)


def _launch(kernel, dim, device: torch.device, stream, *args) -> None:
    """Launch ``kernel`` on the CPU, or on CUDA in ``stream()`` (a context in which Warp's current stream is ordered
    with torch's: :meth:`~wresdyn.sim.simulator.Simulator._tape_stream`, where the simulator's own Warp work runs) or,
    without one, on torch's current stream."""
    import warp as wp

    # array descriptors, not wp.array objects: a few microseconds each instead of ~10 (Python on the launch path)
    wargs = [wp.from_torch(a, return_ctype=True) if isinstance(a, torch.Tensor) else a for a in args]
    if device.type == "cuda" and stream is not None:
        with stream():
            wp.launch(kernel, dim=dim, inputs=wargs, device=wp.device_from_torch(device))
    elif device.type == "cuda":
        cur = torch.cuda.current_stream(device)
        stream = _streams.get(cur.cuda_stream)
        if stream is None:
            stream = _streams[cur.cuda_stream] = wp.stream_from_torch(cur)
        with wp.ScopedStream(stream, sync_enter=False, sync_exit=False):  # ordered with torch's work by the stream
            wp.launch(kernel, dim=dim, inputs=wargs, device=stream.device)
    else:
        wp.launch(kernel, dim=dim, inputs=wargs, device="cpu")


class _Observe(torch.autograd.Function):
    """[q, q̇, q̈, cmd] (+ noise), (N, 4n), of q, q̇ (given twice: see the module's text), the previous q̇ (``diff``)
    or q̈ itself, cmd and noise (N, 4n) or ``None``; with the Warp kernels (``kernel``) or the torch operators."""

    @staticmethod
    def forward(ctx, q, qd, qd_again, prev, cmd, noise, dt: float, diff: bool, kernel: bool, stream):
        n, dtype = q.shape[1], q.dtype
        ctx.n, ctx.diff, ctx.dt, ctx.kernel, ctx.stream = n, diff, dt, kernel, stream
        if not kernel:
            obs = torch.cat([q, qd, (qd - prev) / dt if diff else prev, cmd], dim=-1)
            return obs if noise is None else obs.add_(noise)
        forward, _ = _kernels(dtype)
        scale, recip = _scale(dt, q.device, dtype)
        obs = torch.empty((q.shape[0], 4 * n), dtype=dtype, device=q.device)
        _launch(forward, (q.shape[0], n), q.device, stream, q.detach(), qd.detach(), prev.detach(), cmd.detach(),
                None if noise is None else noise.detach(), scale, recip, int(diff), int(noise is not None), obs)
        return obs

    @staticmethod
    def backward(ctx, adj_obs):
        n, (need_q, need_qd, need_again, need_prev) = ctx.n, ctx.needs_input_grad[:4]
        adj_q = adj_obs[:, :n] if need_q else None
        adj_qd = adj_obs[:, n:2 * n] if need_qd else None
        adj_again = adj_prev = None
        if not ctx.diff:
            adj_prev = adj_obs[:, 2 * n:3 * n] if need_prev else None
        elif (need_again or need_prev) and not ctx.kernel:  # the division's and then the subtraction's backward
            adj_again = adj_obs[:, 2 * n:3 * n] / ctx.dt
            adj_prev = -adj_again if need_prev else None
        elif need_again or need_prev:
            _, backward = _kernels(adj_obs.dtype)
            scale, recip = _scale(ctx.dt, adj_obs.device, adj_obs.dtype)
            out = torch.empty((2, adj_obs.shape[0], n), dtype=adj_obs.dtype, device=adj_obs.device)
            _launch(backward, (adj_obs.shape[0], n), adj_obs.device, ctx.stream, adj_obs, scale, recip, out)
            adj_again, adj_prev = out[0], out[1]
        return (adj_q, adj_qd, adj_again if need_again else None, adj_prev if need_prev else None,
                None, None, None, None, None, None)


def observe(q: torch.Tensor, qd: torch.Tensor, prev: torch.Tensor, cmd: torch.Tensor, noise: torch.Tensor | None,
            dt: float, diff: bool = True, kernel: bool = True, stream=None) -> torch.Tensor:
    """The observation ``observation(q, qd, (qd - prev) / dt, cmd) + noise`` as one autograd node, the same values and
    gradients (bit for bit); with ``kernel`` in one Warp kernel each way.

    Args:
        q: Joint positions [rad], (N, n).
        qd: Joint velocities [rad/s], (N, n).
        prev: The previous step's joint velocities [rad/s], (N, n); with ``diff`` False the joint accelerations
            [rad/s²] themselves (a rollout's first step, which observes the recorded q̈).
        cmd: Commanded joint positions [rad], (N, n) (no gradient).
        noise: Observation noise added to the whole observation, (N, 4n), or ``None`` (no gradient).
        dt: Sample period [s] the accelerations are differences over.
        diff: Whether ``prev`` is the previous velocity (q̈ = (q̇ − prev) / dt) or q̈.
        kernel: The Warp kernels (one launch each way), else the torch operators inside the node.
        stream: On CUDA, a callable giving the context to launch the kernels in (a rollout's
            ``sim._tape_stream``, the simulator's own Warp streams); ``None``: torch's current stream.

    Returns:
        The observation (N, 4n), differentiable in ``q``, ``qd`` and ``prev``.
    """
    return _Observe.apply(q, qd, qd, prev, cmd, noise, float(dt), bool(diff), bool(kernel), stream)
