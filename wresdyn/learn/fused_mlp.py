"""The MLP residual inside a differentiable rollout in fewer torch kernels per step (the gradient fit's opt-in
``fused_network``, :class:`~wresdyn.fit.gradfit_config.GradFitConfig`).

Through the plain path each step of the rollout runs the network's forward and, in the backward pass, autograd's
per-layer backward: a GEMM for the layer input's gradient, one for the weight's, a bias sum and two additions into the
parameters' gradients (four layers: 16 kernels a step for the parameters alone), and the clip's backward as four
kernels. On a GPU these small kernels are launch-bound (``benchmarks/results/speed/gradfit10_plan.md``: ~73 torch
kernels a step at ~2.4 µs each). :class:`FusedMLPRollout` runs the same network with

* the parameters' gradients formed once per iteration: each step writes its layers' inputs and the gradients at their
  outputs into (H, B, ·) buffers, and :meth:`FusedMLPRollout.finish` turns them into each weight's gradient with one
  GEMM over all H·B rows (from :data:`SPLIT_ROWS` rows one per step, summed) and each bias's with one matrix-vector
  product (8 to 12 kernels an iteration instead of 16 a step);
* the clip's mask kept from the forward pass (one comparison), its backward one ``where``.

The forward values, the residual and the gradient each step passes back to the simulated state are the plain path's
operations on the same operands (equal bit for bit on the CPU, ``tests/learn/test_fused_mlp.py``). The parameters'
gradients are the same sums in another order (one GEMM over H·B rows instead of H GEMMs over B rows added up step by
step), so they agree with autograd's to float32 rounding only; that is why the path is opt-in. With the tile kernels
(``tiles``) a rollout hands the state itself (:meth:`FusedMLPRollout.residual_and_action_from_state`), from which the
forward kernel forms the observation.
"""

from __future__ import annotations

import torch
import torch.nn as nn

from .residual import MLPResidualPolicy, residual_grad
from .tile_mlp import TileMLP

__all__ = ["FusedMLPRollout", "SPLIT_ROWS", "fusable"]

SPLIT_ROWS = 32768
"""Rows (steps x windows) from which :meth:`FusedMLPRollout.finish` forms each weight's gradient as one product per
step, summed (at 1024 windows: windows of 32 and 64 steps)."""


def fusable(policy) -> str | None:
    """Why ``policy`` cannot run as a :class:`FusedMLPRollout`, or ``None`` if it can: an
    :class:`~wresdyn.learn.residual.MLPResidualPolicy` at gain 1 without a second normaliser, its network linear
    layers with ELU between them."""
    if not isinstance(policy, MLPResidualPolicy):
        return f"{type(policy).__name__} is not an MLP residual"
    if policy.gain != 1.0 or not isinstance(policy.norm, nn.Identity):
        return "the fused MLP runs residuals at gain 1 without a second normaliser (the gradient fit's)"
    layers = list(policy.mlp)
    linear, act = layers[0::2], layers[1::2]
    if not all(isinstance(m, nn.Linear) and m.bias is not None for m in linear) or len(linear) != len(act) + 1 \
            or not all(isinstance(m, nn.ELU) and m.alpha == act[0].alpha for m in act):
        return "the network is not linear layers with one ELU between them"
    return None


class _Step(torch.autograd.Function):
    """One step of :class:`FusedMLPRollout`: raw observation -> residual, and with ``both`` the action residual / scale
    too. ``token`` is a leaf that requires grad so the step is in the backward graph even where the observation
    carries no gradient (a window's first step, a step after truncation): its backward is what stores the gradients at
    the layer outputs."""

    @staticmethod
    def forward(ctx, obs, token, run, k, both, out):
        ctx.run, ctx.k = run, k
        ctx.set_materialize_grads(False)
        return run._forward(obs, k, out, both)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_r, g_a=None):
        return ctx.run._backward(g_r, g_a, ctx.k, ctx.needs_input_grad[0]), None, None, None, None, None


class _StateStep(torch.autograd.Function):
    """:class:`_Step` with the observation formed inside the tile kernel from the rollout's state (q, q̇ and the q̇
    before, which carry gradients; the first step's q̈, the command and the noise, which do not)."""

    @staticmethod
    def forward(ctx, q, qd, before, token, run, k, out, rate, cmd, noise, dt):
        ctx.run, ctx.k, ctx.dt = run, k, dt
        ctx.set_materialize_grads(False)
        return run._tiles.forward_state(q, qd, before, rate, cmd, noise, dt, k, out, True)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_r, g_a=None):
        needs = ctx.needs_input_grad[:3]
        grads = ctx.run._tiles.backward_state(g_r, g_a, ctx.k, any(needs), ctx.dt)
        return (*(g if n else None for g, n in zip(grads, needs)), *[None] * 8)


class FusedMLPRollout(nn.Module):
    """Stands in for an :class:`~wresdyn.learn.residual.MLPResidualPolicy` in one differentiable rollout
    (:func:`wresdyn.sim.rollout` with ``grad=True``): :meth:`begin` before it, the rollout's steps (one call each),
    the loss's ``backward()``, then :meth:`finish`, which adds the parameters' gradients to their ``.grad`` as
    autograd would (set where ``None``, added otherwise). Its calls outside that order are refused.

    With ``tiles`` (float32 networks) each step's forward and backward run as one Warp tile kernel each
    (:class:`~wresdyn.learn.tile_mlp.TileMLP`, split as ``tile_block`` says, a
    :class:`~wresdyn.learn.tile_mlp.TileBlock`; where ``None``, ``$WRESDYN_TILE_BLOCK``'s or the defaults) instead of
    the torch operations below: the same buffers, equal to float32 rounding.

    Example::

        fused = FusedMLPRollout(policy)
        fused.begin(window.steps, window.cmd.shape[0])
        run = rollout(sim, window, fused, grad=True)
        loss(run).backward()
        fused.finish()
    """

    def __init__(self, policy, tiles: bool = False, tile_block=None) -> None:
        super().__init__()
        why = fusable(policy)
        if why is not None:
            raise ValueError(f"cannot fuse this residual: {why}")
        self.policy = policy
        self.kind = policy.kind
        self.linears = list(policy.mlp)[0::2]
        self.alpha = float(policy.mlp[1].alpha) if len(self.linears) > 1 else 1.0
        dev = policy.obs_mean.device
        self._token = torch.ones((), device=dev, requires_grad=True)
        self._zero = torch.zeros((), device=dev)  # clamp's backward writes this 0-dim zero where the clip holds
        self._steps, self._k = 0, 0
        self._x = self._z = self._g = self._mask = None
        self._ones: dict[int, torch.Tensor] = {}  # the bias gradients' vectors of ones, per row count
        self._tiles = None
        if tiles:
            if policy.obs_mean.dtype != torch.float32:
                raise ValueError("the tile kernels run float32 networks")
            dims = [self.linears[0].in_features] + [m.out_features for m in self.linears]
            self._tiles = TileMLP(dims, self.alpha, dev, tile_block)

    @property
    def scale(self) -> torch.Tensor:
        return self.policy.scale

    @property
    def obs_std(self) -> torch.Tensor:
        return self.policy.obs_std

    def begin(self, steps: int, batch: int) -> None:
        """Buffers for a rollout of ``steps`` steps over ``batch`` windows: per layer its input (H, B, in), each hidden
        layer's pre-activation, the gradients at the layer outputs (zeros: a step whose backward never runs adds
        nothing) and the clip's mask."""
        w = self.policy.obs_mean
        ins = [m.in_features for m in self.linears]
        outs = [m.out_features for m in self.linears]
        self._x = [torch.empty(steps, batch, d, device=w.device, dtype=w.dtype) for d in ins]
        self._z = [torch.empty(steps, batch, d, device=w.device, dtype=w.dtype) for d in outs[:-1]]
        self._g = [torch.zeros(steps, batch, d, device=w.device, dtype=w.dtype) for d in outs]
        self._mask = torch.empty(steps, batch, outs[-1], device=w.device, dtype=torch.bool)
        self._steps, self._k = steps, 0
        if self._tiles is not None:
            self._tiles.bind(self.policy, self.linears, self._x, self._z, self._g, self._mask)

    def reset(self) -> None:
        """The rollout's start (:func:`wresdyn.sim.rollout` calls it): the next call is step 0."""
        self._k = 0

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self._call(obs, False, None)

    def residual_and_action(self, obs: torch.Tensor, out: torch.Tensor | None = None):
        """(residual, residual / scale) of one step, as :meth:`MLPResidualPolicy.residual_and_action
        <wresdyn.learn.residual.MLPResidualPolicy.residual_and_action>` (the rollout's action in the same node, the
        residual written into ``out`` where given)."""
        return self._call(obs, True, out)

    @property
    def takes_state(self) -> bool:
        """Whether :meth:`residual_and_action_from_state` runs: the tile kernels form the observation themselves."""
        return self._tiles is not None

    def residual_and_action_from_state(self, q, qd, before, rate, cmd, noise, dt: float, out=None):
        """:meth:`residual_and_action` of the observation [q, q̇, q̈, q_cmd] + ``noise[k]`` formed inside the tile
        kernel (:meth:`TileMLP.forward_state <wresdyn.learn.tile_mlp.TileMLP.forward_state>`: ``before`` the q̇ before,
        ``None`` at the window's first step, whose q̈ is ``rate``), where a rollout would run four torch kernels to
        form it and autograd four more to take it apart; the gradients reach q, q̇ and ``before``."""
        self._next()
        return _StateStep.apply(q, qd, before, self._token, self, self._k - 1, out, rate, cmd, noise, dt)

    def backward_state_into(self, k: int, g_r, g_a, need: bool, dt: float, q_grad, qd_grad, before_grad) -> None:
        """Step ``k``'s backward of :meth:`residual_and_action_from_state` from the gradients of its residual and
        action (N, n) each, adding those of q, q̇ and the q̇ before into ``q_grad``, ``qd_grad``, ``before_grad``
        where ``need`` (:meth:`TileMLP.backward_state_into <wresdyn.learn.tile_mlp.TileMLP.backward_state_into>`):
        the rollout of :mod:`wresdyn.sim.tape_chain`, which sums the state's gradients in place."""
        self._tiles.backward_state_into(g_r, g_a, k, need, dt, q_grad, qd_grad, before_grad)

    def _next(self) -> None:
        if self._x is None or self._k >= self._steps:
            raise RuntimeError("FusedMLPRollout: call begin(steps, batch) before each rollout, one call per step")
        self._k += 1

    def _call(self, obs: torch.Tensor, both: bool, out):
        self._next()
        return _Step.apply(obs, self._token, self, self._k - 1, both, out)

    def _forward(self, obs: torch.Tensor, k: int, out: torch.Tensor | None, both: bool):
        if self._tiles is not None:
            return self._tiles.forward(obs, k, out, both)
        r = self._torch_forward(obs, k, out)
        return (r, r / self.policy.scale) if both else r

    def _torch_forward(self, obs: torch.Tensor, k: int, out: torch.Tensor | None) -> torch.Tensor:
        # the plain path's operations in its order: (obs - mean) / std, then per layer addmm (what F.linear runs on a
        # 2-D input) and ELU, then the clip and the scale
        p = self.policy
        x = torch.div(obs - p.obs_mean, p.obs_std, out=self._x[0][k])
        last = len(self.linears) - 1
        for i, lin in enumerate(self.linears):
            if i == last:
                y = torch.addmm(lin.bias, x, lin.weight.t())
                break
            z = torch.addmm(lin.bias, x, lin.weight.t(), out=self._z[i][k])
            x = torch._C._nn.elu(z, self.alpha, out=self._x[i + 1][k])
        c = y.clamp(-1.0, 1.0)
        # clamp's backward passes the gradient where min <= y <= max; c == y is that set in one kernel (NaN: neither)
        torch.eq(c, y, out=self._mask[k])
        if out is None:
            return c * p.scale
        # a fresh view as the step's output: autograd marks it, not the tensor the caller handed in
        return torch.mul(c, p.scale, out=out).view(c.shape)

    def _backward(self, grad, g_action, k: int, need_obs: bool) -> torch.Tensor | None:
        if self._tiles is not None:
            return self._tiles.backward(grad, g_action, k, need_obs)
        p = self.policy
        grad = residual_grad(grad, g_action, p.scale, self._g[-1][k])
        g = torch.where(self._mask[k], grad * p.scale, self._zero, out=self._g[-1][k])
        for i in range(len(self.linears) - 1, -1, -1):
            w = self.linears[i].weight
            if i == 0:
                # the normalisation's backward: sub passes the gradient through, div divides by std
                return torch.mm(g, w) / p.obs_std if need_obs else None
            g = torch.ops.aten.elu_backward.grad_input(torch.mm(g, w), self.alpha, 1, 1, False, self._z[i - 1][k],
                                                      grad_input=self._g[i - 1][k])
        return None

    def finish(self) -> None:
        """After the backward pass: each layer's weight gradient as one GEMM over the steps' and windows' rows, each
        bias's as one sum, added to the parameters' ``.grad`` (set where ``None``); the buffers are released."""
        if self._x is None or self._k != self._steps:
            raise RuntimeError(f"FusedMLPRollout.finish after {self._k} of {self._steps} steps")
        rows = self._x[0].shape[0] * self._x[0].shape[1]
        ones = self._ones.get(rows)
        if ones is None:  # one per row count, made by the first (eager) iteration at it and kept: a graph reads it
            ones = self._ones[rows] = torch.ones(rows, device=self._x[0].device, dtype=self._x[0].dtype)
        for lin, x, g in zip(self.linears, self._x, self._g):
            # autograd's weight gradient of addmm(b, x, W.t()) is mm(g.t(), x), its bias's g.sum(0): here over all
            # rows at once. From SPLIT_ROWS rows on the weight's as H products of B rows, summed, where one product
            # over all rows has a few output tiles for a whole GPU (89 µs for the first layer at H = 64, B = 1024 on an
            # H200, benchmarks/results/speed/h200_20261201c/); the bias's as a matrix-vector product, where torch's
            # column sum over those rows took 58 µs
            g_rows = g.view(rows, -1)
            weight = torch.bmm(g.transpose(1, 2), x).sum(0) if rows >= SPLIT_ROWS else \
                torch.mm(g_rows.t(), x.view(rows, -1))
            for param, new in ((lin.weight, weight), (lin.bias, torch.mv(g_rows.t(), ones))):
                if param.grad is None:
                    param.grad = new
                else:
                    param.grad.add_(new)
        self._x = self._z = self._g = self._mask = None
        self._steps = self._k = 0
        if self._tiles is not None:
            self._tiles.bind()
