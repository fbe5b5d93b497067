"""A no-gradient rollout captured whole as one CUDA graph, replayed on every later call with the same inputs' shapes.

An open-loop replay without gradients (model selection's validation replays, above all) is, on a GPU, bound by the
per-step Python and launch overhead of :func:`~wresdyn.sim.rollout.rollout`'s loop (the policy, the simulator step,
the divergence bookkeeping: small kernels each), not by the work. Captured once as one graph, a later replay is a
single launch. The loop's body is branch-free without gradients (no host read; divergence is tracked with masks), so
the captured graph does what the eager loop does, world for world.

What a graph depends on is its key (:func:`rollout_key`): the shapes of the window, the noise and the open-loop
residual, the policy object with the storage of its parameters and buffers (an optimiser updates them in place,
which the graph then reads; a module moved or rebuilt is a new key), the residual kind, the policy's worlds and the
divergence limits. The window's tensors, the noise and the residual are copied into the graph's own buffers before
each replay, so the caller may pass new tensors of the same shapes. The graph reads and writes the simulator's state
buffer that was current at its capture: where a replay of an odd step count left the other one current, the state is
copied over first (the simulator's states ping-pong). The physical parameters are read from the model's arrays,
which :meth:`~wresdyn.sim.simulator.Simulator.set_physics` writes in place; a solver that recompiles on a change
clears the cache (``Simulator._physics_changed``).

A key is first run eagerly on the simulator's stream (Warp modules loaded, torch warmed up), captured and replayed
at its second call, replayed after; a capture that fails (a policy reading the host) warns and leaves the key eager.
The eager runs take the host-read loop: where a key never gets to its capture (a solver that clears the cache at
each :meth:`~wresdyn.sim.simulator.Simulator.set_physics`), the masks at every step would only cost.
Python-side state a policy keeps between its own steps (a GRU's hidden state) lives inside the loop, reset at its
start, so the graph replays it too; state changed between calls other than in parameters and buffers (a Python
attribute) is not seen, hence the policy object is part of the key.
"""

from __future__ import annotations

import dataclasses
import warnings

import torch

from .bank import Window

__all__ = ["capture_blocker", "rollout_key", "run_captured", "MAX_GRAPHS"]

MAX_GRAPHS = 4
"""Captured rollouts a simulator keeps (each holds its memory pool); the oldest goes first."""

_WINDOW_FIELDS = ("q", "qd", "qdd", "cmd", "target", "length")
_WARM = "warm"  # a key run eagerly once, captured at its next call
_EAGER = "eager"  # a key whose capture failed: it runs eagerly from then on


def capture_blocker(device, *, grad: bool, enabled: bool, policy=None, policy_device=None, obs_noise: float = 0.0,
                    noise: torch.Tensor | None = None) -> str | None:
    """Why a rollout is not captured as a CUDA graph, or ``None`` where it is.

    ``device``: the simulator's torch device; ``policy_device``: that of the policy's parameters (``None`` for
    none); ``noise``: the observation noise given up front (a fixed buffer) or ``None`` (drawn per step from a
    generator when ``obs_noise`` > 0, which a graph would replay as the same draws).
    """
    if not enabled:
        return "switched off (Simulator.rollout_graph or graph=False)"
    if torch.device(device).type != "cuda":
        return "not on CUDA"
    if grad:
        return "gradients (a differentiable rollout keeps its tapes per step)"
    if policy is not None and not isinstance(policy, torch.nn.Module):
        return "the policy is not a torch module"
    if policy_device is not None and torch.device(policy_device) != torch.device(device):
        return "the policy is on another device than the simulator"
    if obs_noise > 0.0 and noise is None:
        return "observation noise drawn from a generator at each step"
    return None


def _shape(t) -> tuple | None:
    return None if t is None else (tuple(t.shape), t.dtype)


def rollout_key(sim, window: Window, policy, kind: str, policy_worlds: slice | None, residual, obs_noise: float,
                noise, limits) -> tuple:
    """What a captured rollout depends on (see the module docstring); equal keys replay the same graph."""
    pol = None
    if policy is not None:
        tensors = list(policy.parameters()) + list(policy.buffers())
        pol = (id(policy), type(policy), policy.training, tuple((t.data_ptr(), tuple(t.shape)) for t in tensors))
    pw = None if policy_worlds is None else (policy_worlds.start, policy_worlds.stop, policy_worlds.step)
    return (tuple(_shape(getattr(window, f)) for f in _WINDOW_FIELDS), pol, kind, pw, _shape(residual),
            float(obs_noise), _shape(noise), limits)


def run_captured(sim, key: tuple, window: Window, noise, residual, body, keep=None):
    """``body(window, noise, residual, masked)`` (a :class:`~wresdyn.sim.rollout.Rollout`; ``masked``: the
    branch-free loop) run through the simulator's graph of ``key``: run eagerly (its default loop) at the key's first
    call, captured (branch-free) and replayed at its second, replayed after. ``keep``: an object the graph reads (the
    policy), held with it. Returns outputs of their own (not the graph's buffers)."""
    cache = sim._rollout_graphs
    entry = cache.get(key)
    cur, side = torch.cuda.current_stream(sim.device), sim.side_stream()
    side.wait_stream(cur)
    if entry is _WARM:
        try:
            entry = _capture(sim, window, noise, residual, body, keep)
        except RuntimeError as e:  # something in the loop that a graph cannot hold (a host read in a policy)
            warnings.warn(f"rollout not captured as a CUDA graph, it runs eagerly: {e}", RuntimeWarning, stacklevel=3)
            entry = _EAGER
        _remember(cache, key, entry)
    if entry is None or entry is _EAGER:  # eager, on the simulator's stream as the capture is
        _remember(cache, key, entry or _WARM)  # warm even where it raises (a diverged replay): the kernels are loaded
        try:
            with torch.cuda.stream(side):
                return body(window, noise, residual)
        finally:
            cur.wait_stream(side)
    graph, static, static_noise, static_residual, out, start, after, _ = entry
    if sim._cur != start:  # the whole joint state, base included: what the eager loop would start from
        sim._q[start].copy_(sim._q[sim._cur])
        sim._qd[start].copy_(sim._qd[sim._cur])
        sim._cur = start
    for f in _WINDOW_FIELDS:
        getattr(static, f).copy_(getattr(window, f))
    if noise is not None:
        static_noise.copy_(noise)
    if residual is not None:
        static_residual.copy_(residual)
    graph.replay()
    sim._cur = after
    return dataclasses.replace(out, **{f.name: None if getattr(out, f.name) is None else getattr(out, f.name).clone()
                                       for f in dataclasses.fields(out)})


def _remember(cache: dict, key: tuple, value) -> None:
    cache.pop(key, None)
    cache[key] = value  # most recent last
    while len(cache) > MAX_GRAPHS:
        cache.pop(next(iter(cache)))


def _capture(sim, window: Window, noise, residual, body, keep) -> tuple:
    """Capture ``body`` on the simulator's stream, its Warp launches in the same graph (the solver's own per-step
    graph is switched off meanwhile: it would nest). The simulator's buffer index is restored: nothing ran."""
    import warp as wp

    static = Window(*(getattr(window, f).clone() for f in _WINDOW_FIELDS))
    static_noise = None if noise is None else noise.clone()
    static_residual = None if residual is None else residual.clone()
    graph, side, start, solver_graph = torch.cuda.CUDAGraph(), sim.side_stream(), sim._cur, sim.graph
    sim.graph = False
    try:
        with torch.cuda.graph(graph, stream=side, capture_error_mode="thread_local"):
            wp.capture_begin(stream=sim._wp_side, external=True, capture_mode=wp.CaptureMode.THREAD_LOCAL)
            try:
                out = body(static, static_noise, static_residual, True)
            finally:
                wp.capture_end(stream=sim._wp_side)
    finally:
        sim.graph = solver_graph
        after, sim._cur = sim._cur, start
    return graph, static, static_noise, static_residual, out, start, after, keep
