"""The differentiable sample period of :meth:`wresdyn.sim.Simulator.step_diff`: one ``torch.autograd.Function`` whose
backward runs the step's Warp tape.

Each step ``k`` of a rollout has buffers of its own (:class:`TapeBuffers`: Newton states and a control, kept for the
backward pass) and torch views of the arrays it reads and writes, made once: copying the inputs in and the gradients
out through these views costs one torch copy each, where wrapping the tensors for Warp at every call
(``wp.from_torch``, ``wp.to_torch``, ``wp.copy``) cost about a quarter of a CPU gradient-fit iteration at 32 windows.
"""

from __future__ import annotations

import torch

__all__ = ["TapeBuffers", "TapeStep"]


class TapeBuffers:
    """One step's Newton states (``substeps + 1``) and control, and (N, width) torch views of the arrays the step
    reads (q, q̇, PD target, joint force), of their gradients, and of the last state's q, q̇ and their gradients;
    ``index``: where the actuated joints' values sit in each of the four (``Simulator.q_index``/``qd_index``). The
    entries outside it are never written (zeros, as allocated)."""

    def __init__(self, model, substeps: int, num_worlds: int, nq: int, nqd: int, q_index, qd_index) -> None:
        import warp as wp

        self.states = [model.state(requires_grad=True) for _ in range(substeps + 1)]
        self.control = model.control(requires_grad=True)
        first, last, ctrl = self.states[0], self.states[-1], self.control
        inputs = (first.joint_q, first.joint_qd, ctrl.joint_target_q, ctrl.joint_f)
        widths = (nq, nqd, nq, nqd)
        self.index = (q_index, qd_index, q_index, qd_index)

        def view(a, width):
            return wp.to_torch(a, requires_grad=False).view(num_worlds, width)

        self.inputs = [view(a, w) for a, w in zip(inputs, widths)]
        self.input_grads = [view(a.grad, w) for a, w in zip(inputs, widths)]
        self.outputs = [view(last.joint_q, nq), view(last.joint_qd, nqd)]
        self.output_grads = [view(last.joint_q.grad, nq), view(last.joint_qd.grad, nqd)]


class TapeStep(torch.autograd.Function):
    """One differentiable sample period: (q, q̇, PD target, joint torque) -> (q', q̇'), each (N, n)."""

    @staticmethod
    def forward(ctx, q, qd, target, tau, sim, k: int, names: tuple = (), *physics):
        """Step ``k`` of ``sim`` from (q, q̇) with the PD target and joint torque, recorded on a Warp tape; ``names``:
        the model fields in ``physics`` whose gradients the backward returns."""
        import warp as wp

        buf = sim._tape_buffers[k]
        for dst, x, index in zip(buf.inputs, (q, qd, target, tau), buf.index):
            dst[:, index] = x  # on torch's current stream, which step_diff's Warp work follows (_tape_stream)
        tape = wp.Tape()
        with sim._tape_stream():
            with tape:
                if sim._needs_fk:
                    sim._eval_fk(buf.states[0])
                for s in range(sim.substeps):
                    sim.solver.step(buf.states[s], buf.states[s + 1], buf.control, None, sim.dt_sub)
        ctx.tape, ctx.sim, ctx.k, ctx.names = tape, sim, k, names
        ctx.physics_meta = [(p.dtype, p.device) for p in physics]
        return tuple(out[:, index].clone() for out, index in zip(buf.outputs, buf.index))

    @staticmethod
    def backward(ctx, g_q, g_qd):
        """Run the step's tape backwards from the gradients of (q', q̇'); return those of the inputs and fields."""
        sim, tape = ctx.sim, ctx.tape
        buf = sim._tape_buffers[ctx.k]
        for f in ctx.names:  # the parameters' gradients accumulate over every step's tape: start this one at 0
            sim._model_view(f, grad=True).zero_()
        for dst, g, index in zip(buf.output_grads, (g_q, g_qd), buf.index):
            dst[:, index] = g
        with sim._tape_stream():
            tape.backward()
        out = tuple(g[:, index].clone() for g, index in zip(buf.input_grads, buf.index))
        physics = sim._physics_grads(ctx.names, ctx.physics_meta)
        with sim._tape_stream():
            if ctx.names or sim.solver_kind != "replay" or getattr(sim.solver, "update_body_q", False):
                tape.zero()
            else:  # SolverReplay adds into the inputs' gradients only (the outputs' are overwritten next time):
                # zero those, not the 13 parameter arrays no one reads here (one memset each, every step)
                for st in buf.states[:-1]:
                    st.joint_q.grad.zero_()
                    st.joint_qd.grad.zero_()
                for a in (buf.control.joint_target_q, buf.control.joint_target_qd, buf.control.joint_f):
                    a.grad.zero_()
        ctx.tape = None
        return (*out, None, None, None, *physics)
