"""Launching SolverReplay's generated kernels cheaply on the CPU: a recorded launch called directly, and the key
under which a solver keeps its recorded launches."""

from __future__ import annotations

import ctypes

import warp as wp

__all__ = ["cpu_call", "grad_of", "launch_signature"]


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
