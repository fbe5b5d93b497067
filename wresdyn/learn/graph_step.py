"""A window learner's optimiser step replayed from a CUDA graph, one graph per window length.

The gradient fit (:mod:`wresdyn.fit.gradfit`) and identification (:mod:`wresdyn.identify.sysid`) take thousands of
steps at a few tens of windows, where the GPU idles and the host's kernel launches set the pace (the forward and
backward Warp launches of each solver step, torch's small ops, Adam). :class:`StepGraphs` runs a step so that, from
the second call at a window length on, it is one graph launch:

- the first call at a length runs eagerly on the simulator's own stream (Warp modules loaded, Adam's state and
  torch's workspaces made, none of which a capture may do);
- the second is captured (torch's capture, which the Warp launches join as an external capture on the same stream,
  :meth:`~wresdyn.sim.Simulator._tape_stream`) and replayed; later calls are replayed;
- the step's per-call inputs (window indices, observation noise) enter through buffers kept with the graph, copied
  into before each replay; its output (the loss parts) is a tensor in the graph's memory, cloned after the replay;
- the gradients are allocated by the captured backward, in the graph's memory pool (they are set to ``None`` first).

What a graph reads besides its inputs (parameters, Adam's state, the learning rate as a device tensor with Adam
``capturable``: :func:`adopt_optimiser`) must keep its storage: an event that replaces such a tensor, or changes
what the step does on the host (which parameters have a gradient), calls :meth:`StepGraphs.reset`, and the next
calls warm up and capture again.
"""

from __future__ import annotations

import torch

__all__ = ["StepGraphs", "adopt_optimiser", "set_lr"]


def adopt_optimiser(optim, device, capturable: bool, fused: bool = False) -> None:
    """Put Adam's learning rate and step count where a captured step wants them (``capturable``: a device tensor
    each) or where an eager one does (a float, a CPU tensor; on the device for ``fused``); again after a checkpoint's
    optimiser state is loaded, which brings its own flags."""
    for group in optim.param_groups:
        group["capturable"] = capturable
        group["fused"] = fused or None
        lr = float(group["lr"])
        group["lr"] = torch.tensor(lr, device=device) if capturable else lr
    for state in optim.state.values():
        if "step" in state:
            state["step"] = state["step"].to(device if capturable or fused else "cpu", torch.float32)


def set_lr(group: dict, lr: float) -> None:
    """Set a parameter group's learning rate: in place where it is a device tensor (a graph reads it), else the
    float."""
    if torch.is_tensor(group["lr"]):
        group["lr"].fill_(lr)
    else:
        group["lr"] = lr


class _Captured:
    """A captured step: its graph, the kept input buffers and its output in the graph's memory."""

    def __init__(self, graph, out: torch.Tensor) -> None:
        self.graph, self.out = graph, out

    def replay(self) -> torch.Tensor:
        self.graph.replay()
        return self.out.clone()


class StepGraphs:
    """Calls of a step ``run(*inputs) -> Tensor`` on ``sim``'s stream, captured per key (see the module).

    Example: ``graphs(h, run, traj, start)`` runs ``run(traj, start)`` eagerly at the first call with key ``h``,
    captures it at the second and replays it from then on, with ``traj``, ``start`` copied into the graph's own
    buffers (``None`` inputs stay ``None``).
    """

    def __init__(self, sim, before_capture=None) -> None:
        self.sim = sim
        self.before_capture = before_capture
        """Called before each warm-up and capture (``None``: nothing): where a learner drops the autograd graphs it
        keeps from eager work, whose gradient accumulators would tie the captured backward to another stream."""
        self._warm: set = set()
        self._graphs: dict = {}  # key -> (captured, kept inputs)

    @staticmethod
    def available(device) -> bool:
        """Whether steps on ``device`` can be captured (CUDA)."""
        return torch.device(device).type == "cuda"

    def reset(self) -> None:
        """Forget every graph and warm-up: the next call at each key runs eagerly again, the one after captures."""
        self._warm.clear()
        self._graphs.clear()

    def __call__(self, key, run, *inputs):
        if key not in self._warm:
            self._warm.add(key)
            self._before()
            return self._on_side_stream(lambda: run(*inputs))
        entry = self._graphs.get(key)
        if entry is None:
            kept = tuple(None if x is None else x.clone() for x in inputs)
            self._before()
            entry = self._graphs[key] = (self._capture(lambda: run(*kept)), kept)
        captured, kept = entry
        for buf, x in zip(kept, inputs):
            if x is not None:
                buf.copy_(x)
        return captured.replay()

    def _before(self) -> None:
        if self.before_capture is not None:
            self.before_capture()

    def _on_side_stream(self, fn):
        """``fn()`` on the simulator's stream, ordered after the current stream's work and before its later work."""
        sim = self.sim
        cur, side = torch.cuda.current_stream(sim.device), sim.side_stream()
        side.wait_stream(cur)
        with torch.cuda.stream(side):
            out = fn()
        cur.wait_stream(side)
        return out

    def _capture(self, fn) -> _Captured:
        """``fn`` captured (not run) on the simulator's stream, its Warp launches joining torch's capture."""
        import warp as wp

        sim = self.sim
        side = sim.side_stream()
        side.wait_stream(torch.cuda.current_stream(sim.device))
        graph = torch.cuda.CUDAGraph()
        with torch.cuda.graph(graph, stream=side, capture_error_mode="thread_local"):
            wp.capture_begin(stream=sim._wp_side, external=True, capture_mode=wp.CaptureMode.THREAD_LOCAL)
            try:
                out = fn()
            finally:
                wp.capture_end(stream=sim._wp_side)
        return _Captured(graph, out)
