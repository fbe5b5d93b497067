"""The differentiable sample period of :meth:`wresdyn.sim.Simulator.step_diff`: one ``torch.autograd.Function``
whose backward runs the step's Warp tape.

Each step ``k`` of a rollout has buffers of its own (:class:`TapeBuffers`: Newton states and a control, kept for the
backward pass) and torch views of the arrays it reads and writes, made once: copying the inputs in and the gradients
out through these views costs one torch copy each, where wrapping the tensors for Warp at every call
(``wp.from_torch``, ``wp.to_torch``, ``wp.copy``) cost about a quarter of a CPU gradient-fit iteration at 32 windows.

On a GPU each copy and memset of a step is a kernel of its own, about 2 µs each in a chain of small kernels, so the
buffers are laid out for fewer of them:

* where the actuated joints are the whole state (a fixed base), step ``k + 1`` reads its q, q̇ from step ``k``'s
  output arrays (Warp aliases, with gradients of their own): the value a rollout hands on is already in place;
* the forward returns views of the output arrays and the backward views of the input gradients, not copies: both
  hold until the step runs again (the next rollout), longer than autograd needs them (it copies a leaf's gradient
  into ``.grad``; do not keep the gradients ``torch.autograd.grad`` returns for the step's inputs across rollouts);
* the gradients SolverReplay's adjoint adds into (the inputs') are rows of a few arrays (:class:`TapeGradients`),
  each zeroed in one memset by the first step of a rollout that finds it used, not five memsets a step.
"""

from __future__ import annotations

import torch

__all__ = ["TapeBuffers", "TapeGradients", "TapeStep"]


class TapeGradients:
    """The gradient arrays of the steps' inputs, float32 rows of ``width`` values, one row per step, in arrays of
    doubling length (steps 0-7, 8-23, 24-55, ...: four at 64 steps). An array whose rows a backward pass used is zeroed
    before the next forward step in it; the adjoint then adds into zeros, as it needs."""

    FIRST = 8
    """Rows of the first array; the ``c``-th holds ``FIRST · 2^c``."""

    def __init__(self, device) -> None:
        self.device = device
        self.arrays: list = []
        self.used: list[bool] = []

    @classmethod
    def _where(cls, k: int) -> tuple[int, int]:
        """(array, row) of step ``k``: array ``c`` holds steps FIRST·(2^c − 1) to FIRST·(2^(c+1) − 1) − 1."""
        c = (k // cls.FIRST + 1).bit_length() - 1
        return c, k - cls.FIRST * ((1 << c) - 1)

    def row(self, k: int, width: int):
        """Step ``k``'s row, a Warp float32 array (width,)."""
        import warp as wp

        c, r = self._where(k)
        while len(self.arrays) <= c:
            self.arrays.append(wp.zeros((self.FIRST << len(self.arrays), width), dtype=wp.float32,
                                        device=self.device))
            self.used.append(False)
        if self.arrays[c].shape[1] != width:
            raise ValueError(f"step {k}: gradient row of {width} values, the arrays have {self.arrays[c].shape[1]}")
        return self.arrays[c][r]

    def clear(self, k: int) -> None:
        """Before step ``k``'s forward: zero its array if a backward pass used it (on the current Warp stream)."""
        c = self._where(k)[0]
        if self.used[c]:
            self.arrays[c].zero_()
            self.used[c] = False

    def mark(self, k: int) -> None:
        """Step ``k``'s backward pass left gradients in its row."""
        self.used[self._where(k)[0]] = True


def _alias(a):
    """A Warp array on ``a``'s memory with a gradient array of its own."""
    import warp as wp

    return wp.array(ptr=a.ptr, dtype=a.dtype, shape=a.shape, device=a.device, requires_grad=True)


class TapeBuffers:
    """One step's Newton states (``substeps + 1``) and control, and (N, width) torch views of the arrays the step
    reads (q, q̇, PD target, joint force), of their gradients, and of the last state's q, q̇ and their gradients;
    ``index``: where the actuated joints' values sit in each of the four (``Simulator.q_index``/``qd_index``). The
    entries outside it are never written (zeros, as allocated).

    ``grads``: where the gradients the adjoint adds into live (step ``k``'s row); ``prev``: the previous step's
    buffers, whose output q, q̇ this step reads in place where ``index`` covers the whole state (``chained``)."""

    def __init__(self, model, substeps: int, num_worlds: int, nq: int, nqd: int, q_index, qd_index,
                 grads: TapeGradients | None = None, k: int = 0, prev: TapeBuffers | None = None) -> None:
        import warp as wp

        self.states = [model.state(requires_grad=True) for _ in range(substeps + 1)]
        self.control = model.control(requires_grad=True)
        first, last, ctrl = self.states[0], self.states[-1], self.control
        whole = isinstance(q_index, slice) and isinstance(qd_index, slice) \
            and (q_index, qd_index) == (slice(0, nq), slice(0, nqd))
        self.chained = whole and prev is not None
        if self.chained:
            first.joint_q, first.joint_qd = _alias(prev.states[-1].joint_q), _alias(prev.states[-1].joint_qd)
        if grads is not None:
            added = self.accumulated()
            row = grads.row(k, sum(a.size for a in added))
            start = 0
            for a in added:
                a.grad = row[start:start + a.size]
                start += a.size
        inputs = (first.joint_q, first.joint_qd, ctrl.joint_target_q, ctrl.joint_f)
        widths = (nq, nqd, nq, nqd)
        self.index = (q_index, qd_index, q_index, qd_index)

        def view(a, width):
            return wp.to_torch(a, requires_grad=False).view(num_worlds, width)

        self.inputs = [view(a, w) for a, w in zip(inputs, widths)]
        self.input_grads = [view(a.grad, w) for a, w in zip(inputs, widths)]
        self.outputs = [view(last.joint_q, nq), view(last.joint_qd, nqd)]
        self.output_grads = [view(last.joint_q.grad, nq), view(last.joint_qd.grad, nqd)]
        # kept here, so autograd never takes one over as a leaf's .grad or adds into it in place
        self.grad_views = [g[:, i] if isinstance(i, slice) else None for g, i in zip(self.input_grads, self.index)]

    @classmethod
    def up_to(cls, sim, k: int) -> None:
        """Make ``sim``'s buffers of the steps up to ``k`` where missing, and zero step ``k``'s input gradients if a
        backward pass used them (on the current Warp stream)."""
        bufs = sim._tape_buffers
        while len(bufs) <= k:
            bufs.append(cls(sim.model, sim.substeps, sim.num_worlds, sim.nq, sim.nqd, sim.q_index, sim.qd_index,
                            sim._tape_grads, len(bufs), bufs[-1] if bufs else None))
        sim._tape_grads.clear(k)

    def accumulated(self) -> list:
        """The arrays whose gradients SolverReplay's adjoint adds into: every state's q, q̇ but the last's (the last
        one's are the incoming gradient, overwritten) and the control's three."""
        c = self.control
        return [a for st in self.states[:-1] for a in (st.joint_q, st.joint_qd)] + [c.joint_target_q,
                                                                                   c.joint_target_qd, c.joint_f]

    def input_grad(self, i: int, copy: bool = False) -> torch.Tensor:
        """The gradient of input ``i`` (q, q̇, target, force) the last backward pass left: a view (``copy``: a copy),
        or a gather where the index is not a slice."""
        v = self.grad_views[i]
        if v is None:
            return self.input_grads[i][:, self.index[i]]
        return v.clone() if copy else v


def _same(x: torch.Tensor, view: torch.Tensor) -> bool:
    """Whether ``x`` is ``view`` (the same memory, shape, strides and dtype), so copying it in would change nothing."""
    return (x.data_ptr() == view.data_ptr() and x.shape == view.shape and x.stride() == view.stride()
            and x.dtype == view.dtype and x.device == view.device)


class TapeStep(torch.autograd.Function):
    """One differentiable sample period: (q, q̇, PD target, joint torque) -> (q', q̇'), each (N, n)."""

    @staticmethod
    def forward(ctx, q, qd, target, tau, sim, k: int, names: tuple = (), *physics):
        """Step ``k`` of ``sim`` from (q, q̇) with the PD target and joint torque, recorded on a Warp tape; ``names``:
        the model fields in ``physics`` whose gradients the backward returns."""
        import warp as wp

        buf = sim._tape_buffers[k]
        for i, (dst, x, index) in enumerate(zip(buf.inputs, (q, qd, target, tau), buf.index)):
            if i < 2 and buf.chained and _same(x, dst):  # the previous step's output, in place already
                continue
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
        # views: the outputs stay until this step runs again (a gather where the index is not a slice)
        return tuple(out[:, index] for out, index in zip(buf.outputs, buf.index))

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
        # SolverReplay adds into the inputs' gradients only (the outputs' are overwritten next time), and those are
        # zeroed before the next rollout (TapeGradients): hand out views of them. Other solvers, and parameter
        # gradients, zero the whole tape after each step: copies.
        kept = not ctx.names and sim.solver_kind == "replay" and not getattr(sim.solver, "update_body_q", False)
        need = ctx.needs_input_grad[:4]
        out = tuple(buf.input_grad(i, copy=not kept) if n else None for i, n in enumerate(need))
        physics = sim._physics_grads(ctx.names, ctx.physics_meta)
        if kept:
            sim._tape_grads.mark(ctx.k)
        else:
            with sim._tape_stream():
                tape.zero()
        ctx.tape = None
        return (*out, None, None, None, *physics)
