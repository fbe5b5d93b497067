"""PD-only window rollouts in one solver launch: :meth:`SolverReplay.rollout` under a :class:`~wresdyn.sim.simulator.
Simulator`, differentiable to the physical parameters.

:func:`~wresdyn.sim.rollout.rollout` steps the simulator from Python, one launch (and, with gradients, one Warp tape)
per sample period. Without a residual policy in the loop nothing needs the state between steps, so the replay
solver can run every step of a window batch in one launch and, backwards, every step's adjoint in one plan: the same
kernels, the same arithmetic (:func:`fused_rollout` matches :func:`~wresdyn.sim.rollout.rollout` to float32
rounding), far fewer launches. Online identification (:mod:`wresdyn.adapt`) replays its windows this way.
"""

from __future__ import annotations

import torch

from .bank import Window
from .simulator import Simulator

__all__ = ["can_fuse", "fused_rollout"]


def can_fuse(sim: Simulator) -> bool:
    """Whether ``sim`` can replay PD-only windows in one launch: the replay solver at one substep, and no servo drive
    (whose goal profile and dead band carry state the fused launch does not)."""
    return sim.solver_kind == "replay" and sim.substeps == 1 and getattr(sim.robot, "servo", None) is None


def fused_rollout(sim: Simulator, window: Window) -> tuple[torch.Tensor, torch.Tensor]:
    """Replay ``window`` open loop from its recorded start state, PD only, every step in one launch.

    ``sim`` runs the replay solver, one sample period per step (``substeps = 1``), one world per window. Physical
    parameters set with :meth:`~wresdyn.sim.simulator.Simulator.set_physics` as tensors that require grad (with
    ``Simulator(requires_grad=True, param_grads=True)``) receive gradients, summed over worlds, as through
    :meth:`~wresdyn.sim.simulator.Simulator.step_diff`, and so do targets that require grad (a delay being
    identified shifts them); the start state is data (no gradient).

    Returns:
        ``(q, qd)``: joint positions [rad] and velocities [rad/s], each (B, L + 1, n): the start state, then the
        state after each step. No divergence handling: a diverged world shows up as non-finite values.
    """
    if sim.solver_kind != "replay" or sim.substeps != 1:
        raise ValueError(f"fused_rollout needs the replay solver at one substep (got {sim.solver_kind}, "
                         f"{sim.substeps} substeps)")
    if window.cmd.shape[0] != sim.num_worlds:
        raise ValueError(f"window batch {window.cmd.shape[0]} != simulator worlds {sim.num_worlds}")
    names = tuple(sim._physics) if torch.is_grad_enabled() else ()
    q, qd = _Fused.apply(window.q[:, 0], window.qd[:, 0], window.target, sim, names,
                         *(sim._physics[f] for f in names))
    return q, qd


def _layout(x: torch.Tensor, index: torch.Tensor, width: int) -> torch.Tensor:
    """(B, L, n) actuated-joint values -> (L, B, width) time-major in Newton's per-world layout, zeros elsewhere."""
    out = torch.zeros(x.shape[1], x.shape[0], width, dtype=torch.float32, device=x.device)
    out[:, :, index] = x.transpose(0, 1).to(torch.float32)
    return out


def _buffers(sim: Simulator, steps: int, grad: bool, grad_target: bool) -> tuple:
    """Warp arrays (q, q̇, target) for a batch of ``steps``, time-major in Newton's layout: a free set of an earlier
    rollout of the same shape, or new ones. The solver keys its launch plans by the arrays' addresses, so reusing
    them spares rebuilding a plan of ``steps`` launches (forward and adjoint) at every call."""
    import warp as wp

    key = (steps, grad, grad_target)
    free = sim.__dict__.setdefault("_fused_free", {}).get(key)
    if free:
        return free.pop()
    w, dev = sim.num_worlds, sim.model.device
    return (wp.zeros((steps + 1, w, sim.nq), dtype=wp.float32, device=dev, requires_grad=grad),
            wp.zeros((steps + 1, w, sim.nqd), dtype=wp.float32, device=dev, requires_grad=grad),
            wp.zeros((steps, w, sim.nq), dtype=wp.float32, device=dev, requires_grad=grad_target))


def _release(sim: Simulator, arrays: tuple, grad: bool, grad_target: bool) -> None:
    """Give ``arrays`` back for the next rollout of their shape (once nothing reads them any more: after the forward
    without gradients, after the backward with; their gradients are zero then)."""
    sim._fused_free.setdefault((arrays[2].shape[0], grad, grad_target), []).append(arrays)


class _Fused(torch.autograd.Function):
    """(start state, PD targets, physical parameters) -> the window's (q, q̇), each (B, L + 1, n)."""

    @staticmethod
    def forward(ctx, q0, qd0, target, sim: Simulator, names: tuple, *physics):
        import warp as wp

        steps = target.shape[1]
        grad_target = ctx.needs_input_grad[2]
        grad = bool(names) or grad_target
        arrays = _buffers(sim, steps, grad, grad_target)
        q, qd, tgt = (wp.to_torch(a, requires_grad=False) for a in arrays)
        q[0] = _layout(q0[:, None], sim.q_index, sim.nq)[0]  # rows 1.. are the rollout's to write
        qd[0] = _layout(qd0[:, None], sim.qd_index, sim.nqd)[0]
        tgt.copy_(_layout(target, sim.q_index, sim.nq))
        tape = wp.Tape() if grad else None
        with sim._tape_stream():
            if grad:
                with tape:
                    sim.solver.rollout(*arrays, sim.dt)
            else:
                sim.solver.rollout(*arrays, sim.dt)
        ctx.tape, ctx.sim, ctx.names, ctx.arrays = tape, sim, names, arrays
        ctx.physics_meta = [(p.dtype, p.device) for p in physics]
        ctx.shape, ctx.target_dtype = q0.shape, (target.dtype if grad_target else None)
        out = (q.transpose(0, 1)[:, :, sim.q_index].clone(), qd.transpose(0, 1)[:, :, sim.qd_index].clone())
        if not grad:
            _release(sim, arrays, grad, grad_target)
            ctx.arrays = None
        return out

    @staticmethod
    def backward(ctx, g_q, g_qd):
        import warp as wp

        sim, tape, (q, qd, target) = ctx.sim, ctx.tape, ctx.arrays
        for f in ctx.names:
            sim._model_view(f, grad=True).zero_()
        with sim._tape_stream():
            tape.backward(grads={q: wp.from_torch(_layout(g_q, sim.q_index, sim.nq).contiguous()),
                                 qd: wp.from_torch(_layout(g_qd, sim.qd_index, sim.nqd).contiguous())})
        physics = sim._physics_grads(ctx.names, ctx.physics_meta)
        g_target = None
        if ctx.target_dtype is not None:  # (T, B, width) in Newton's layout -> (B, T, n)
            # a copy: the tape's zeroing below would clear a view of its gradient array
            g_target = wp.to_torch(target.grad)[:, :, sim.q_index].transpose(0, 1).to(ctx.target_dtype, copy=True)
        with sim._tape_stream():
            tape.zero()
        _release(sim, ctx.arrays, True, ctx.target_dtype is not None)
        ctx.tape = ctx.arrays = None
        return (None, None, g_target, None, None, *physics)
