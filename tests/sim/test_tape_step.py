""":mod:`wresdyn.sim.tape_step`'s buffers laid out for fewer copies and memsets a step (the next step reading the last
one's output in place, views handed out instead of copies, the input gradients zeroed once per rollout) against the
form they replace, a copy in and out of every value and the gradients zeroed after each step's backward: the same
rollout and gradients, bit for bit, on the CPU. The same Warp kernels run in both; a stale gradient, a view read
after it changed or a leaf's ``.grad`` left pointing into a buffer would show as a difference."""

import numpy as np
import pytest
import torch

from wresdyn.sim import Simulator
from wresdyn.sim.tape_step import StepRows, stage_targets

DT = 0.002


class _CopiedStep(torch.autograd.Function):
    """The replaced form of :class:`~wresdyn.sim.tape_step.TapeStep` (SolverReplay, no parameter gradients), written
    out: every input copied in, the outputs and the input gradients copied out, the input gradients zeroed after."""

    @staticmethod
    def forward(ctx, q, qd, target, tau, sim, k):
        import warp as wp

        from wresdyn.sim.tape_step import TapeBuffers

        TapeBuffers.up_to(sim, k)
        buf = sim._tape_buffers[k]
        for dst, x, index in zip(buf.inputs, (q, qd, target, tau), buf.index):
            dst[:, index] = x
        tape = wp.Tape()
        with tape:
            sim.solver.step(buf.states[0], buf.states[1], buf.control, None, sim.dt_sub)
        ctx.tape, ctx.sim, ctx.k = tape, sim, k
        return tuple(out[:, index].clone() for out, index in zip(buf.outputs, buf.index))

    @staticmethod
    def backward(ctx, g_q, g_qd):
        buf = ctx.sim._tape_buffers[ctx.k]
        for dst, g, index in zip(buf.output_grads, (g_q, g_qd), buf.index):
            dst[:, index] = g
        ctx.tape.backward()
        out = tuple(g[:, index].clone() for g, index in zip(buf.input_grads, buf.index))
        for a in buf.accumulated():
            a.grad.zero_()
        return (*out, None, None)


def _inputs(robot, b, h, seed, staged):
    """Start state, PD targets and torques; the targets without gradients where a rollout stages them."""
    rng = np.random.default_rng(seed)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -0.5)
    hi = np.where(np.isfinite(robot.upper), robot.upper, 0.5)
    mid, half = (lo + hi) / 2, np.minimum((hi - lo) / 2, 0.5)
    f = lambda x: torch.tensor(x, dtype=torch.float32, requires_grad=True)  # noqa: E731
    return {"q0": f(mid + 0.3 * half * rng.uniform(-1, 1, (b, robot.n_dof))),
            "qd0": f(rng.uniform(-1, 1, (b, robot.n_dof))),
            "target": f(mid + 0.3 * half * rng.uniform(-1, 1, (b, h, robot.n_dof))).requires_grad_(not staged),
            "tau": f(0.03 * np.minimum(robot.effort, 100.0) * rng.uniform(-1, 1, (b, h, robot.n_dof)))}


def _run(sim, x, copied: bool):
    """A rollout whose states each feed the next step, an observation-like product, a finite difference and the loss
    (several consumers each, as the gradient fit's), with a detached state half-way (truncation)."""
    q, qd, qs, total = x["q0"], x["qd0"], [], 0.0
    h = x["target"].shape[1]
    staged = None if copied else stage_targets(sim, x["target"])
    for k in range(h):
        target = x["target"][:, k] if staged is None else staged[k]
        args = (q, qd, target, x["tau"][:, k] * (1.0 + 0.1 * q.sin()))
        q_new, qd_new = _CopiedStep.apply(*args, sim, k) if copied else sim.step_diff(k, *args)
        total = total + (((qd_new - qd) / DT) ** 2).sum() * 1e-6
        q, qd = q_new, qd_new
        qs.append(q)
        if k == h // 2:
            q, qd = q.detach(), qd.detach()
    q_all = torch.stack(qs, 1)
    loss = total + (q_all ** 2).sum() + 0.01 * (qd ** 2).sum()
    loss.backward()
    return [q_all.detach(), loss.detach(), *(v.grad for v in x.values() if v.requires_grad)]


# 26 steps: rows in the second and third arrays; targets with gradients are copied in a step at a time, without staged
@pytest.mark.parametrize("b, h, staged", [(3, 10, False), (2, 26, True)])
def test_buffers_in_place_give_the_copied_results_bit_for_bit(humanoid, b, h, staged):
    sim = Simulator(humanoid, b, DT, solver="replay", requires_grad=True)
    first, second = _inputs(humanoid, b, h, 0, staged), _inputs(humanoid, b, h, 1, staged)
    fast = _run(sim, first, copied=False)
    kept = [t.clone() for t in fast]
    fast2 = _run(sim, second, copied=False)  # the buffers' values and gradients all change
    for a, b_ in zip(fast, kept):  # nothing the first rollout handed out points into the buffers
        assert torch.equal(a, b_)
    ref_sim = Simulator(humanoid, b, DT, solver="replay", requires_grad=True)
    for x, out in ((first, fast), (second, fast2)):
        ref = _run(ref_sim, {k: v.detach().clone().requires_grad_(v.requires_grad) for k, v in x.items()}, copied=True)
        assert len(ref) == len(out) == 6 - staged
        for i, (a, r) in enumerate(zip(out, ref)):
            assert torch.equal(a, r), i
    # the layout these savings rest on: each step after the first reads the last one's output arrays in place
    bufs = sim._tape_buffers
    assert not bufs[0].chained and all(buf.chained for buf in bufs[1:])
    assert bufs[1].inputs[0].data_ptr() == bufs[0].outputs[0].data_ptr()
    assert (stage_targets(sim, first["target"]) is None) == (not staged)


def test_gradient_rows_lie_in_arrays_of_doubling_length():
    where = [StepRows._where(k) for k in range(120)]
    assert where[0] == (0, 0) and where[7] == (0, 7) and where[8] == (1, 0) and where[23] == (1, 15)
    assert where[24] == (2, 0) and where[55] == (2, 31) and where[56] == (3, 0) and where[63] == (3, 7)
    assert len({c for c, _ in where[:64]}) == 4  # 64 steps: four memsets a rollout instead of five a step


@pytest.mark.parametrize("b, h, staged", [(2, 26, True), (3, 10, False)])
def test_a_simulator_without_rows_gives_the_same_rollouts(humanoid, b, h, staged):
    """The layout a CUDA simulator takes with WRESDYN_TAPE_ROWS=0 (``tape_rows`` gives ``None``: each step's own
    buffers, every value copied, the adjoint's gradients zeroed after each step), taken on the CPU: two
    rollouts in a row give the rows' results bit for bit, and nothing is chained or staged."""
    rows, plain = (Simulator(humanoid, b, DT, solver="replay", requires_grad=True) for _ in range(2))
    plain._tape_rows = None  # what tape_rows returns on CUDA with WRESDYN_TAPE_ROWS=0, before any step is made
    for seed in (0, 1):
        x = _inputs(humanoid, b, h, seed, staged)
        a = _run(rows, x, copied=False)
        r = _run(plain, {k: v.detach().clone().requires_grad_(v.requires_grad) for k, v in x.items()}, copied=False)
        for i, (u, v) in enumerate(zip(a, r)):
            assert torch.equal(u, v), (seed, i)
    assert not any(buf.chained for buf in plain._tape_buffers)
    assert stage_targets(plain, x["target"]) is None


def test_tape_rows_are_on_everywhere_unless_switched_off_on_cuda(monkeypatch):
    from wresdyn.sim.tape_step import CUDA_ROWS_ENV, TapeRows, tape_rows

    monkeypatch.delenv(CUDA_ROWS_ENV, raising=False)
    assert isinstance(tape_rows("cpu"), TapeRows) and isinstance(tape_rows("cuda:0"), TapeRows)
    monkeypatch.setenv(CUDA_ROWS_ENV, "0")
    assert tape_rows("cuda:0") is None and isinstance(tape_rows("cpu"), TapeRows)
