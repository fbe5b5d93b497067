"""A differentiable rollout of SolverReplay with a torque residual that forms its observation from the state, as one
autograd node whose backward runs each step's two kernels in reverse, adding into the state's gradient where it lies.

Through :func:`~wresdyn.sim.rollout`'s step loop each step is two autograd nodes (the residual's, the solver's) and
each state feeds four (the loss, the next residual and solver step, and the residual after through q̈); autograd sums
their gradients a torch kernel at a time, about six small kernels and two copies a step on a GPU, as much GPU time
as the residual's backward kernel. Here a state's gradient is a row of the simulator's
:class:`~wresdyn.sim.tape_step.StepRows`, which the step before reads as its output's gradient
(:class:`~wresdyn.sim.tape_step.TapeBuffers`): the loss's gradients are copied into the rows, a few copies for the
whole window, and the solver's adjoint and the residual's backward kernel add into them. The values are the step
loop's; the gradients are the same sums in another order (float32 rounding).

It runs where the step loop would hand the residual the state itself (a policy with ``takes_state`` and
``backward_state_into``, the gradient fit's tile kernels, :class:`~wresdyn.learn.fused_mlp.FusedMLPRollout`), with
SolverReplay, no physical parameters carrying gradients, and a state that is the actuated joints alone (a fixed base);
``WRESDYN_ROLLOUT_CHAIN=0`` keeps the step loop there, for comparison.
"""

from __future__ import annotations

import os

import torch

from .tape_step import TapeBuffers, record_step

__all__ = ["CHAIN_ENV", "chains", "chained_rollout"]

CHAIN_ENV = "WRESDYN_ROLLOUT_CHAIN"
"""Set to 0 to run a rollout that could be chained through the step loop (two autograd nodes a step)."""

_TOKENS: dict = {}  # device -> a leaf that requires grad: puts the rollout's node into the backward graph


def chains(sim, policy) -> bool:
    """Whether :func:`chained_rollout` runs ``sim``'s differentiable rollout with ``policy`` (module docstring)."""
    rows = sim._tape_rows
    return (os.environ.get(CHAIN_ENV) != "0" and rows is not None and sim.solver_kind == "replay"
            and not getattr(sim.solver, "update_body_q", False) and not sim._physics
            and getattr(policy, "takes_state", False) and hasattr(policy, "backward_state_into"))


def chained_rollout(sim, window, policy, targets: list, forces: list, noise: torch.Tensor | None,
                    truncation: int = 0):
    """The differentiable rollout of ``window`` (B worlds) with ``policy`` in the loop: ``(q, q̇, actions)``, (B, H + 1,
    n) states [rad, rad/s] from the recorded start and the normalised residuals (B, H, n). ``targets``, ``forces``:
    the steps' staged PD targets and joint-torque views (:func:`~wresdyn.sim.tape_step.stage_targets`,
    :func:`~wresdyn.sim.tape_step.step_forces`); ``noise``: the observation noise, scaled, (H, B, 4n) or ``None``;
    ``truncation``: no gradient flows back past every this many steps (0: never), as the step loop's detach."""
    device = window.q.device
    token = _TOKENS.get(device)
    if token is None:
        token = _TOKENS[device] = torch.ones((), device=device, requires_grad=True)
    return _Chain.apply(token, sim, window, policy, targets, forces, noise, truncation)


class _Chain(torch.autograd.Function):
    @staticmethod
    def forward(ctx, token, sim, window, policy, targets, forces, noise, truncation):
        q, qd, rate = window.q[:, 0], window.qd[:, 0], window.qdd[:, 0]
        qs, qds, actions, tapes, before = [q], [qd], [], [], None
        for k in range(window.steps):
            r, a = policy.residual_and_action_from_state(q, qd, before, rate, window.cmd[:, k], noise, sim.dt,
                                                         forces[k])
            with sim._tape_stream():  # Warp fills new buffers on the stream whose torch writes to them come next
                TapeBuffers.up_to(sim, k)
            tape, (q_new, qd_new) = record_step(sim, k, q, qd, targets[k], r)
            tapes.append(tape)
            actions.append(a)
            q, qd, before = q_new, qd_new, qd
            qs.append(q)
            qds.append(qd)
        ctx.sim, ctx.policy, ctx.tapes, ctx.truncation = sim, policy, tapes, truncation
        return torch.stack(qs, 1), torch.stack(qds, 1), torch.stack(actions, 1)

    @staticmethod
    @torch.autograd.function.once_differentiable
    def backward(ctx, g_q, g_qd, g_a):
        sim, policy, tapes, t = ctx.sim, ctx.policy, ctx.tapes, ctx.truncation
        h, bufs, rows = len(tapes), sim._tape_buffers, sim._tape_rows.grads
        _rows_from(rows, bufs[0], g_q, g_qd, h)
        for j in reversed(range(h)):
            if t and (j + 1) % t == 0 and j + 1 < h:
                # the state after step j was detached for the steps after it: its gradient is the loss's alone
                for dst, g in zip(bufs[j].output_grads, (g_q, g_qd)):
                    dst.copy_(g[:, j + 1])
            with sim._tape_stream():
                tapes[j].backward()
            grads = bufs[j].input_grads
            need = j > 0 and not (t and j % t == 0)  # the state the residual read carries a gradient
            policy.backward_state_into(j, grads[3], g_a[:, j], need, sim.dt, grads[0], grads[1],
                                       bufs[j - 1].input_grads[1] if j else None)
        for _, k0, _ in rows.spans(h + 1):
            rows.mark(k0)  # each array of rows zeroed before a step adds into it again
        ctx.tapes = None
        return (None,) * 8


def _rows_from(rows, buf, g_q: torch.Tensor, g_qd: torch.Tensor, h: int) -> None:
    """Copy the loss's gradients of states 1 .. ``h`` (B, h + 1, n) into their rows of ``rows``, one copy of each per
    array of rows; the rows of steps 1 .. h - 1 are zero (the forward's steps cleared them) and row h is written
    nowhere else."""
    b, nq, nqd = g_q.shape[0], buf.inputs[0].shape[1], buf.inputs[1].shape[1]
    for c, k0, k1 in rows.spans(h + 1):
        lo = max(k0, 1)
        if lo >= k1:
            continue
        part = rows.view(c)[lo - k0:k1 - k0]
        part[:, :b * nq].view(-1, b, nq).copy_(g_q[:, lo:k1].transpose(0, 1))
        part[:, b * nq:b * (nq + nqd)].view(-1, b, nqd).copy_(g_qd[:, lo:k1].transpose(0, 1))
