"""Launching SolverReplay's generated kernels: cheaply on the CPU (a recorded launch called directly), under the key
a solver keeps its recorded launches by, and the solver's launch side (:class:`LaunchPlans`): its worlds in chunks
over CPU threads, each chunk's launches recorded once and replayed, the adjoint's launches, the ``wp.Tape``
registration."""

from __future__ import annotations

import ctypes
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp

from .kernels import lane_width

__all__ = ["cpu_call", "grad_of", "launch_signature", "LaunchPlans"]


def cpu_call(cmd):
    """A CPU launch as a direct call of the compiled entry point with argument structs built once.

    ``Launch.launch`` rebuilds the ctypes argument structs on every call (~20 us for this kernel's ~30
    arguments, twice that for an adjoint), which dominates a step of one world. Uses Warp internals
    (pinned to 1.19); returns None where they differ, and the caller falls back to ``Launch.launch``.
    """
    try:
        if not cmd.device.is_cpu or cmd.block_dim != 1:
            return None
        args, adj = wp._src.context._build_cpu_args_structs(cmd.kernel, cmd.hooks, cmd.params, cmd.adjoint)
        bounds = cmd.params[0]
        if cmd.adjoint:
            fn, refs = cmd.hooks.backward, (ctypes.byref(bounds), ctypes.byref(args), ctypes.byref(adj))
        else:
            fn, refs = cmd.hooks.forward, (ctypes.byref(bounds), ctypes.byref(args))
    except (AttributeError, TypeError, ValueError):
        return None

    def call(fn=fn, refs=refs, _keep=(cmd, args, adj, bounds)):  # the structs and module must outlive the call
        fn(*refs)

    return call


def grad_of(a):
    """The gradient array of a launch argument that carries one, else None."""
    if isinstance(a, wp.array):
        return a.grad if a.requires_grad else None
    return None


def launch_signature(a):
    """Launch-cache key of an argument: arrays by address, shape, strides and gradient address."""
    if isinstance(a, wp.array):
        return (a.ptr, a.shape, a.strides, a.grad.ptr if a.requires_grad and a.grad is not None else None)
    return a


class LaunchPlans:
    """The launch side of :class:`~.solver.SolverReplay`, which it reads: ``tree``, ``threads``, ``kernels``,
    ``model``, ``adjoint_pieces``, ``requires_grad`` and the solver's ``_plans``, ``_pool`` and ``_scratch``."""

    def _chunks(self) -> list[tuple[int, int]]:
        w = self.tree.world_count
        n = min(self.threads, w)
        edges = np.linspace(0, w, n + 1).astype(int)
        return [(int(a), int(b - a)) for a, b in zip(edges[:-1], edges[1:]) if b > a]

    def _plan(self, key: tuple, build):
        """Per-chunk lists of launch callables, built once per argument signature ``key``.

        A CPU ``wp.launch`` with ~30 arguments costs tens of microseconds of Python, more than a step of a
        few worlds, so launches are recorded once (``record_cmd``) and replayed; the signature holds the
        arrays' addresses, so new arrays get a new plan."""
        plan = self._plans.get(key)
        if plan is None:
            if len(self._plans) >= 256:
                self._plans.clear()
            plan = self._plans[key] = [build(chunk) for chunk in self._chunks()]
        return plan

    def _command(self, kernel, chunk: tuple[int, int], args: list, outputs: list, adjoint: bool = False):
        """A callable that launches ``kernel(world_start, *args, *outputs)`` (or its adjoint) on one chunk."""
        laned = hasattr(self.kernels, "LANES")  # a thread per world and branch: kernel(world_start, world_end, ...)
        inputs = [chunk[0], *((chunk[0] + chunk[1],) if laned else ()), *args]
        extra = {"block_dim": self.kernels.BLOCK_DIM}  # CUDA: Warp launches at 256 unless told, whatever it built
        if adjoint:
            extra |= {"adj_inputs": [grad_of(a) for a in inputs], "adj_outputs": [grad_of(a) for a in outputs]}
        dim = (self.kernels.LANES, lane_width(chunk[1], self.model.device.is_cuda)) if laned else chunk[1]
        cmd = wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=self.model.device, adjoint=adjoint,
                        record_cmd=True, **extra)
        return cpu_call(cmd) or cmd.launch

    def _execute(self, plan: list) -> None:
        """Run each chunk's launches in order, the chunks concurrently (CPU threads)."""
        if len(plan) == 1:
            for call in plan[0]:
                call()
            return
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=self.threads, thread_name_prefix="replay")
        list(self._pool.map(lambda calls: [call() for call in calls], plan))

    def _adjoint(self, chunk: tuple[int, int], args: list, outputs: list) -> list:
        """The launches of one step's adjoint on ``chunk``: the step kernel's, or with :attr:`adjoint_pieces` the
        chain's (:mod:`.split`): its pieces but the last forward to refill the scratch (they write nothing else),
        the chunk's scratch gradient zeroed, then every piece's adjoint, last to first."""
        if not self.adjoint_pieces:
            return [self._command(self.kernels.replay_step, chunk, args, outputs, adjoint=True)]
        pieces, out = self.kernels.PIECES, [*outputs, self._scratch]
        grad = self._scratch.grad[:, chunk[0]:chunk[0] + chunk[1]]  # this chunk's worlds: chunks run side by side
        return ([self._command(k, chunk, args, out) for k in pieces[:-1]] + [grad.zero_]
                + [self._command(k, chunk, args, out, adjoint=True) for k in reversed(pieces)])

    def _record(self, backward, arrays: list) -> None:
        """Under a recording ``wp.Tape``, register ``backward`` for the arrays that carry gradients."""
        tape = wp._src.context.runtime.tape
        if tape is None:
            return
        if not self.requires_grad:
            raise RuntimeError("SolverReplay under a wp.Tape needs requires_grad=True (model or solver argument)")
        tape.record_func(backward, [a for a in arrays if isinstance(a, wp.array) and a.requires_grad])
