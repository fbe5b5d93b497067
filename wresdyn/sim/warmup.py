"""Compile a robot's simulation kernels up front, with a progress line around it.

Warp compiles a module the first time one of its kernels launches; :class:`~wresdyn.sim.solver_replay.SolverReplay`
generates its kernels per robot, so the first ``collect``, ``fit``, ``train``, ``identify`` or ``eval`` of a new
robot can spend minutes in the compiler (the CPU adjoint of a large robot most of all) before its first step, with
nothing on the terminal. :func:`compile_kernels` builds a one-world :class:`~wresdyn.sim.Simulator` with the
settings the command is about to use and takes one step, between a line that says what is happening and one that
says how long it took. Warp caches the compiled modules on disk (``wp.config.kernel_cache_dir``), so later runs
only load them (well under a second on the SO-101); the command's own simulators then reuse the loaded modules.
"""

from __future__ import annotations

import time
import weakref
from pathlib import Path

from ..errors import WresdynError
from .simulator import Simulator

__all__ = ["VARIANTS", "compile_kernels"]

VARIANTS = {"forward": (False, False), "grad": (True, False), "param_grads": (True, True)}
"""Kernel variants, name -> (``requires_grad``, ``param_grads``) of :class:`~wresdyn.sim.Simulator`: replay
(evaluation, PPO, validation), differentiable in the state and residual (gradient fit), differentiable in the
physical parameters too (identification). Each is its own generated module."""

_DONE: dict[tuple, weakref.ref] = {}
"""(robot object id, solver, device, (variant, id of the physics or None)) -> the robot, for what this process
has compiled already: not compiled or announced again (the weak reference tells a live robot from a new one that got a
freed object's id)."""


def _done(robot, solver, device, variant) -> bool:
    ref = _DONE.get((id(robot), solver, str(device), variant))
    return ref is not None and ref() is robot


def _home(path: str) -> str:
    home = str(Path.home())
    return "~" + path[len(home):] if path.startswith(home + "/") else path


def compile_kernels(robot, rate_hz: float, variants=("forward",), *, solver: str = "auto", device: str | None = "cpu",
                    physics=None, say=None) -> float | None:
    """Compile (or load from Warp's cache) the kernels ``robot`` needs for ``variants`` (names of :data:`VARIANTS`)
    with ``solver`` on ``device``, printing through ``say`` one line before and one after.

    Args:
        robot: The robot (:class:`wresdyn.robot.Robot`) the command simulates.
        rate_hz: Sample rate of its data [Hz] (the step of the warm-up world).
        variants: Kernel variants the command will use, e.g. ``("forward", "grad")`` for ``wresdyn fit``.
        solver, device: As the command's simulators.
        physics: Identified physics the command simulates (:class:`~wresdyn.sim.physics.PhysicalParams`), or
            ``None`` for the robot file's. It matters: ``SolverReplay`` compiles parameters that are zero in the
            robot file (friction, off-diagonal inertia) as constants, so identified physics is another module.
        say: Progress printer, called with one string per line (default: ``print``, flushed).

    Returns:
        Seconds spent, or ``None`` when every variant was already compiled in this process (nothing printed).
    """
    import torch
    import warp as wp

    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        raise WresdynError(f"kernel variant(s) {bad}: choose from {', '.join(VARIANTS)}")
    tag = None if physics is None else id(physics)
    todo = [v for v in dict.fromkeys(variants) if not _done(robot, solver, device, (v, tag))]
    if not todo:
        return None
    say = say or (lambda line: print(line, flush=True))
    wp.init()
    cache = _home(str(wp.config.kernel_cache_dir))
    name = Path(str(robot.source)).name
    what = ", ".join(todo) + ("" if physics is None else "; identified physics")
    say(f"compiling Warp kernels for {name} ({robot.n_dof} joints; {what}): on a robot's first run only, "
        f"minutes for a large one, then loaded from {cache} ...")
    t0 = time.perf_counter()
    for v in todo:
        requires_grad, param_grads = VARIANTS[v]
        sim = Simulator(robot, 1, 1.0 / rate_hz, solver=solver, device=device, requires_grad=requires_grad,
                        param_grads=param_grads)
        if physics is not None:
            sim.set_physics(physics)
        with torch.no_grad():
            sim.step(sim.q)  # hold the start pose for one step: the first launch loads (or compiles) the module
        _DONE[(id(robot), solver, str(device), (v, tag))] = weakref.ref(robot)
    seconds = time.perf_counter() - t0
    say(f"... done in {seconds:.1f} s")
    return seconds
