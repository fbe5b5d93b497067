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
* the forward returns views of the output arrays and the backward views of the input gradients, not copies: the
  outputs hold until the step runs again (the next rollout), an input gradient until the step before writes its
  output's gradient into the same row (below) or the step runs again, longer than autograd needs them (it copies a
  leaf's gradient into ``.grad``; do not keep the gradients ``torch.autograd.grad`` returns for the step's inputs
  across rollouts);
* the gradients SolverReplay's adjoint adds into (the inputs') are rows of a few arrays (:class:`StepRows`), each
  zeroed in one memset by the first step of a rollout that finds it used, not five memsets a step; with a fixed base
  a step's output gradient is the next step's input-gradient row (the same memory), so a rollout that sums a state's
  gradient in place (:mod:`wresdyn.sim.tape_chain`) hands it to the step before without a copy;
* with a fixed base the PD targets are rows of such arrays too: a rollout copies all its targets in at once
  (:func:`stage_targets`), not one copy a step.
"""

from __future__ import annotations

import os

import torch

__all__ = ["StepRows", "TapeBuffers", "TapeRows", "TapeStep", "record_step", "stage_targets", "step_forces",
           "tape_rows"]

CUDA_ROWS_ENV = "WRESDYN_TAPE_ROWS"
"""Set to 0 to give each step of a CUDA simulator its own buffers and a copy of each input, output and gradient
instead of the rows (chained states, rows of gradients zeroed once per rollout, staged targets and torques): the layout
to compare against, the same results to the last digit (``benchmarks/results/speed/h200_20261201c/``). A captured
rollout replays only the zeroing it saw at capture, which the fits' CUDA-graph tests check with rows on
(``tests/learn/test_learner_speed_paths.py``, ``tests/identify/test_sysid_graph.py``)."""


def tape_rows(device) -> TapeRows | None:
    """The :class:`TapeRows` of a simulator on ``device``, or ``None`` for each step's own buffers and a copy of each
    input, output and gradient (on CUDA with :data:`CUDA_ROWS_ENV` set to 0)."""
    cuda = str(device).startswith("cuda")
    return None if cuda and os.environ.get(CUDA_ROWS_ENV) == "0" else TapeRows(device)


class StepRows:
    """Float32 rows of ``width`` values, one per step of a rollout, in Warp arrays of doubling length (steps 0-7, 8-23,
    24-55, ...: four at 64 steps), so that one memset or copy covers many steps. For the input gradients an array whose
    rows a backward pass used is zeroed before the next forward step in it (the adjoint adds into zeros, as it
    needs); for the PD targets a rollout copies its targets into the rows in one copy per array."""

    FIRST = 8
    """Rows of the first array; the ``c``-th holds ``FIRST · 2^c``."""

    def __init__(self, device) -> None:
        self.device = device
        self.arrays: list = []
        self.used: list[bool] = []
        self.views: list = []  # torch views of the arrays, where a caller wants them

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
            raise ValueError(f"step {k}: a row of {width} values, the arrays have {self.arrays[c].shape[1]}")
        return self.arrays[c][r]

    def spans(self, steps: int):
        """(array, first step, end step) of each array holding steps 0 .. ``steps`` − 1."""
        c, k = 0, 0
        while k < steps:
            end = min(steps, k + (self.FIRST << c))
            yield c, k, end
            c, k = c + 1, k + (self.FIRST << c)

    def clear(self, k: int) -> None:
        """Before step ``k``'s forward: zero its array if a backward pass used it (on the current Warp stream)."""
        c = self._where(k)[0]
        if self.used[c]:
            self.arrays[c].zero_()
            self.used[c] = False

    def mark(self, k: int) -> None:
        """Step ``k``'s backward pass left gradients in its row."""
        self.used[self._where(k)[0]] = True

    def view(self, c: int) -> torch.Tensor:
        """Array ``c`` as a torch tensor (rows, width), made once: by the first (eager, not captured) rollout that
        reaches the array."""
        import warp as wp

        while len(self.views) <= c:
            self.views.append(wp.to_torch(self.arrays[len(self.views)], requires_grad=False))
        return self.views[c]


class TapeRows:
    """A simulator's :class:`StepRows`: the input gradients SolverReplay's adjoint adds into, and the PD targets."""

    def __init__(self, device) -> None:
        self.grads, self.targets = StepRows(device), StepRows(device)


def _alias(a, like=None):
    """A Warp array on ``a``'s memory (shaped as ``like``) with a gradient array of its own."""
    import warp as wp

    like = a if like is None else like
    return wp.array(ptr=a.ptr, dtype=like.dtype, shape=like.shape, device=like.device, requires_grad=True)


class TapeBuffers:
    """One step's Newton states (``substeps + 1``) and control, and (N, width) torch views of the arrays the step
    reads (q, q̇, PD target, joint force), of their gradients, and of the last state's q, q̇ and their gradients;
    ``index``: where the actuated joints' values sit in each of the four (``Simulator.q_index``/``qd_index``). The
    entries outside it are never written (zeros, as allocated).

    ``rows``: where the gradients the adjoint adds into live (step ``k``'s rows), and where the actuated joints are
    the whole state (``whole``), the PD target and the last state's q, q̇ gradients (step ``k + 1``'s row,
    ``shared_out``); ``prev``: the previous step's buffers, whose output q, q̇ this step then reads in place
    (``chained``)."""

    def __init__(self, model, substeps: int, num_worlds: int, nq: int, nqd: int, q_index, qd_index,
                 rows: TapeRows | None = None, k: int = 0, prev: TapeBuffers | None = None) -> None:
        import warp as wp

        self.states = [model.state(requires_grad=True) for _ in range(substeps + 1)]
        self.control = model.control(requires_grad=True)
        first, last, ctrl = self.states[0], self.states[-1], self.control
        self.whole = isinstance(q_index, slice) and isinstance(qd_index, slice) \
            and (q_index, qd_index) == (slice(0, nq), slice(0, nqd))
        self.chained = self.whole and prev is not None and rows is not None
        self.shared_out = False
        """Whether the output's gradients are rows of step ``k + 1``'s input gradients (:class:`StepRows`)."""
        if self.chained:
            first.joint_q, first.joint_qd = _alias(prev.states[-1].joint_q), _alias(prev.states[-1].joint_qd)
        if rows is not None and self.whole:
            t = ctrl.joint_target_q
            ctrl.joint_target_q = _alias(rows.targets.row(k, t.size), t)
        if rows is not None:
            added = self.accumulated()
            width = sum(a.size for a in added)
            row = rows.grads.row(k, width)
            start = 0
            for a in added:
                a.grad = row[start:start + a.size]
                start += a.size
            if self.whole:  # the output's gradient is the next step's input's: one array, read where it is added
                self.shared_out = True
                after = rows.grads.row(k + 1, width)
                last.joint_q.grad = after[:last.joint_q.size]
                last.joint_qd.grad = after[last.joint_q.size:last.joint_q.size + last.joint_qd.size]
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
    def up_to(cls, sim, k: int, clear: bool = True) -> None:
        """Make ``sim``'s buffers of the steps up to ``k`` where missing, and (``clear``) zero step ``k``'s input
        gradients if a backward pass used them (on the current Warp stream)."""
        bufs = sim._tape_buffers
        while len(bufs) <= k:
            bufs.append(cls(sim.model, sim.substeps, sim.num_worlds, sim.nq, sim.nqd, sim.q_index, sim.qd_index,
                            sim._tape_rows, len(bufs), bufs[-1] if bufs else None))
        if clear and sim._tape_rows is not None:
            sim._tape_rows.grads.clear(k)

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


def stage_targets(sim, target: torch.Tensor) -> list | None:
    """Copy a differentiable rollout's PD targets (B, H, n) into its steps' buffers at once, one copy per array of
    rows instead of one a step; the H (B, n) views to pass to :meth:`~wresdyn.sim.Simulator.step_diff` in their
    place, which then copies nothing. ``None`` (pass the targets themselves) where the actuated joints are not the
    whole state or the targets carry gradients."""
    h = target.shape[1]
    if h == 0 or target.requires_grad or sim._tape_rows is None:
        return None
    with sim._tape_stream():
        TapeBuffers.up_to(sim, h - 1, clear=False)
    bufs = sim._tape_buffers[:h]
    if not bufs[0].whole:
        return None
    rows = sim._tape_rows.targets
    for c, k0, k1 in rows.spans(h):
        rows.view(c).view(-1, *target[:, 0].shape)[:k1 - k0] = target[:, k0:k1].transpose(0, 1)
    return [b.inputs[2] for b in bufs]


def step_forces(sim, steps: int) -> list | None:
    """Where steps 0 .. ``steps`` − 1 of a differentiable rollout read their joint torque: (B, n) views that a
    residual can be written into (``out=``), so that :meth:`~wresdyn.sim.Simulator.step_diff` given that tensor
    copies nothing; valid until the next rollout writes them. ``None`` where the actuated joints are not the whole
    state, or without :class:`TapeRows`."""
    if sim._tape_rows is None:
        return None
    with sim._tape_stream():
        TapeBuffers.up_to(sim, steps - 1, clear=False)
    bufs = sim._tape_buffers[:steps]
    return [b.inputs[3] for b in bufs] if bufs and bufs[0].whole else None


def _same(x: torch.Tensor, view: torch.Tensor) -> bool:
    """Whether ``x`` is ``view`` (the same memory, shape, strides and dtype), so copying it in would change nothing."""
    return (x.data_ptr() == view.data_ptr() and x.shape == view.shape and x.stride() == view.stride()
            and x.dtype == view.dtype and x.device == view.device)


def record_step(sim, k: int, q, qd, target, tau):
    """Step ``k`` of ``sim`` from (q, q̇) (N, n) with the PD target and joint torque, its inputs copied into the step's
    buffers where they are not there already, recorded on a Warp tape: ``(tape, (q', q̇'))``, the outputs as views of
    the step's buffers (they stay until this step runs again; a gather where the index is not a slice)."""
    import warp as wp

    buf = sim._tape_buffers[k]
    for dst, x, index in zip(buf.inputs, (q, qd, target, tau), buf.index):
        if _same(x, dst):  # in place already: the previous step's output, a staged target
            continue
        dst[:, index] = x  # on torch's current stream, which step_diff's Warp work follows (_tape_stream)
    tape = wp.Tape()
    with sim._tape_stream():
        with tape:
            if sim._needs_fk:
                sim._eval_fk(buf.states[0])
            for s in range(sim.substeps):
                sim.solver.step(buf.states[s], buf.states[s + 1], buf.control, None, sim.dt_sub)
    return tape, tuple(out[:, index] for out, index in zip(buf.outputs, buf.index))


class TapeStep(torch.autograd.Function):
    """One differentiable sample period: (q, q̇, PD target, joint torque) -> (q', q̇'), each (N, n)."""

    @staticmethod
    def forward(ctx, q, qd, target, tau, sim, k: int, names: tuple = (), *physics):
        """Step ``k`` of ``sim`` from (q, q̇) with the PD target and joint torque, recorded on a Warp tape; ``names``:
        the model fields in ``physics`` whose gradients the backward returns."""
        ctx.tape, views = record_step(sim, k, q, qd, target, tau)
        ctx.sim, ctx.k, ctx.names = sim, k, names
        ctx.physics_meta = [(p.dtype, p.device) for p in physics]
        return views if sim._tape_rows is not None else tuple(v.clone() for v in views)

    @staticmethod
    def backward(ctx, g_q, g_qd):
        """Run the step's tape backwards from the gradients of (q', q̇'); return those of the inputs and fields."""
        sim, tape = ctx.sim, ctx.tape
        buf = sim._tape_buffers[ctx.k]
        for f in ctx.names:  # the parameters' gradients accumulate over every step's tape: start this one at 0
            sim._model_view(f, grad=True).zero_()
        for dst, g, index in zip(buf.output_grads, (g_q, g_qd), buf.index):
            dst[:, index] = g
        if buf.shared_out:  # the next step's row holds them now: zeroed before a step adds into it again
            sim._tape_rows.grads.mark(ctx.k + 1)
        with sim._tape_stream():
            tape.backward()
        # SolverReplay adds into the inputs' gradients only (the outputs' are overwritten next time), and those are
        # zeroed before the next rollout (StepRows): hand out views of them. Other solvers, and parameter
        # gradients, zero the whole tape after each step: copies.
        replay = not ctx.names and sim.solver_kind == "replay" and not getattr(sim.solver, "update_body_q", False)
        kept = replay and sim._tape_rows is not None
        need = ctx.needs_input_grad[:4]
        out = tuple(buf.input_grad(i, copy=not kept) if n else None for i, n in enumerate(need))
        physics = sim._physics_grads(ctx.names, ctx.physics_meta)
        if kept:
            sim._tape_rows.grads.mark(ctx.k)
        else:
            with sim._tape_stream():
                if replay:  # without rows: zero the gradients the adjoint adds into, not the whole tape's
                    for a in buf.accumulated():
                        a.grad.zero_()
                else:
                    tape.zero()
        ctx.tape = None
        return (*out, None, None, None, *physics)
