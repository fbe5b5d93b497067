"""Compile a robot's simulation kernels up front, with a progress line around it.

Warp compiles a module the first time one of its kernels launches; :class:`~wresdyn.sim.solver_replay.SolverReplay`
generates its kernels per robot, so the first ``collect``, ``fit``, ``train``, ``identify`` or ``eval`` of a new
robot can spend minutes in the compiler (the CPU adjoint of a large robot most of all) before its first step, with
nothing on the terminal. :func:`compile_kernels` builds a one-world :class:`~wresdyn.sim.Simulator` with the
settings the command is about to use, compiles their step modules side by side (Warp's thread pool) and takes one
step per module, between a line that says what is compiled and one that says how long it took. Warp caches the compiled modules on disk (``wp.config.kernel_cache_dir``), so
later runs only load them (well under a second on the SO-101); the command's own simulators then reuse the loaded
modules.

A robot has two SolverReplay variants, whatever its physical parameters (they are run-time arrays): the forward one
(replay, evaluation, PPO, validation) and the one with an adjoint, which serves both the gradient fit and
identification. Identified physics therefore compiles nothing: stage 2 of ``wresdyn fit`` runs on stage 1's modules.
On CUDA every kernel of both (step, fused rollout and, until the one-kernel adjoint is in Warp's cache, the adjoint's
pieces: :mod:`~wresdyn.sim.solver_replay.split`) compiles in one parallel batch.
"""

from __future__ import annotations

import time
import weakref
from pathlib import Path

from ..errors import WresdynError
from ..robot.description import load_robot
from .devices import require_device
from .first_steps import check_newton
from .goal_profile import profile_modules
from .prebuilt import enable as enable_prebuilt
from .prebuilt import export as export_prebuilt
from .simulator import Simulator
from .solver_replay.kernels import background_compiles, compile_batch, deferred_compile, start_background_compiles

__all__ = ["MODULES", "VARIANTS", "compile_kernels", "warm_up"]

VARIANTS = {"forward": (False, False), "grad": (True, False), "param_grads": (True, True)}
"""Kernel variants, name -> (``requires_grad``, ``param_grads``) of :class:`~wresdyn.sim.Simulator`: replay
(evaluation, PPO, validation), differentiable in the state and residual (gradient fit), differentiable in the
physical parameters too (identification)."""

MODULES = {"forward": "forward", "grad": "adjoint", "param_grads": "adjoint"}
"""Variant -> the module it runs on: the adjoint kernels are the same with or without parameter gradients (the
model's arrays carry gradients or not), so ``grad`` and ``param_grads`` share one."""

_DONE: dict[tuple, weakref.ref] = {}
"""(robot object id, solver, device, module of :data:`MODULES`) -> the robot, for what this process has compiled
already: not compiled or announced again (the weak reference tells a live robot from a new one that got a freed
object's id)."""


def _done(robot, solver, device, module) -> bool:
    ref = _DONE.get((id(robot), solver, str(device), module))
    return ref is not None and ref() is robot


def _first_modules(sims, rollout: bool) -> list:
    """The Warp modules of the replay kernels these simulators launch first (none for other solvers), to compile in
    one batch rather than one after another as each is first launched: the steps, the dynamics terms (each solver's
    friction scale ``fric_m0`` at its first launch) and, with ``rollout``, the fused rollout that identification
    replays its windows with. The adjoint's step comes first, so that the longest compile starts at once (a batch
    runs as many at a time as there are cores); a module the variants share (same code, same cache entry) is listed
    once, so that it is not compiled twice side by side."""
    solvers = sorted((s.solver for s in sims if hasattr(s.solver, "kernels")), key=lambda s: not s.requires_grad)
    names = ("replay_step", "replay_terms", *(("replay_rollout",) if rollout else ()))
    mods, seen = [], set()
    for name in names:
        for solver in solvers:
            module = getattr(solver.kernels, name).module
            key = module.get_module_identifier()
            if key not in seen:
                seen.add(key)
                mods.append(module)
    return mods


def _home(path: str) -> str:
    home = str(Path.home())
    return "~" + path[len(home):] if path.startswith(home + "/") else path


def compile_kernels(robot, rate_hz: float, variants=("forward",), *, solver: str = "auto", device: str | None = "cpu",
                    say=None) -> float | None:
    """Compile (or load from Warp's cache) the kernels ``robot`` needs for ``variants`` (names of :data:`VARIANTS`)
    with ``solver`` on ``device``, printing through ``say`` one line before and one after (the seconds of each
    variant compiled). The robot file's parameter values do not matter: any physics set later runs on these
    modules.

    Args:
        robot: The robot (:class:`wresdyn.robot.Robot`) the command simulates.
        rate_hz: Sample rate of its data [Hz] (the step of the warm-up world).
        variants: Kernel variants the command will use, e.g. ``("forward", "grad")`` for ``wresdyn fit``.
        solver, device: As the command's simulators.
        say: Progress printer, called with one string per line (default: ``print``, flushed).

    Returns:
        Seconds spent, or ``None`` when every variant was already compiled in this process (nothing printed).
    """
    import torch
    import warp as wp

    bad = [v for v in variants if v not in VARIANTS]
    if bad:
        raise WresdynError(f"kernel variant(s) {bad}: choose from {', '.join(VARIANTS)}")
    todo: dict[str, str] = {}  # module -> the first variant asking for it
    for v in variants:
        if not _done(robot, solver, device, MODULES[v]):
            todo.setdefault(MODULES[v], v)
    if not todo:
        return None
    say = say or (lambda line: print(line, flush=True))
    wp.init()
    enable_prebuilt()  # a module the prebuilt kernels hold exactly is copied into the cache, not compiled
    cache = _home(str(wp.config.kernel_cache_dir))
    name = Path(str(robot.source)).name
    say(f"compiling Warp kernels for {name} ({robot.n_dof} joints; {', '.join(todo.values())}): on a robot's first "
        f"run only, minutes for a large one, then loaded from {cache} ...")
    t0 = time.perf_counter()
    sims = {}
    with deferred_compile() as cuda_mods:  # CUDA: every variant's modules, compiled together below
        for module, v in todo.items():
            requires_grad, param_grads = VARIANTS[v]
            sims[module] = Simulator(robot, 1, 1.0 / rate_hz, solver=solver, device=device,
                                     requires_grad=requires_grad, param_grads=param_grads)
    built = time.perf_counter()
    # The modules are independent: Warp compiles them in parallel threads (NVRTC or Clang release the GIL), so a
    # first run waits for the largest one (on CUDA a piece of the adjoint, on the CPU the adjoint) instead of the sum.
    mods = _first_modules(sims.values(), rollout="param_grads" in todo.values())
    mods += [m for m in cuda_mods if m not in mods]
    if len(mods) > 1:
        compile_batch(mods, sims[next(iter(sims))].model.device)
    start_background_compiles()
    parts = []
    for module, v in todo.items():
        with torch.no_grad():
            sims[module].step(sims[module].q)  # hold the start pose for one step: the first launch loads the module
        _DONE[(id(robot), solver, str(device), module)] = weakref.ref(robot)
        shared = [u for u in VARIANTS if MODULES[u] == module and u != v and u in variants]
        parts.append(f"{v}{'' if not shared else ' = ' + ' = '.join(shared)}")
    # one batch compiled every variant's modules: one time covers them all
    parts = [f"{' and '.join(parts)}{' in parallel' if len(todo) > 1 else ''} {time.perf_counter() - built:.1f} s"]
    seconds = time.perf_counter() - t0
    grad = any(VARIANTS[v][0] for v in todo.values())
    later = ("; the adjoint runs in pieces this time, as one kernel (1.3-1.5x faster) from the next run: it compiles "
             "in the background" if grad and background_compiles() else "")
    say(f"... done in {seconds:.1f} s ({', '.join(parts)}{later})")
    return seconds


def _solver_modules(sims) -> list:
    """Every Warp module of the replay kernels of these simulators: the step, the fused rollout (identification and
    the validation replays), the dynamics terms and, on CUDA, the adjoint's pieces."""
    mods = []
    for sim in sims:
        k = getattr(sim.solver, "kernels", None)
        for kernel in () if k is None else (k.replay_step, k.replay_rollout, k.replay_terms, *getattr(k, "PIECES", ())):
            if kernel.module not in mods:
                mods.append(kernel.module)
    return mods


def _cache_entries() -> set[str]:
    import warp as wp

    root = Path(wp.config.kernel_cache_dir)
    return {p.name for p in root.iterdir()} if root.is_dir() else set()


def warm_up(targets, *, device: str = "cpu", rate_hz: float = 500.0, say=None, export: str | None = None) -> int:
    """Compile into Warp's cache every kernel module the default ``fit``, ``identify``, ``train`` (PPO) and ``eval``
    of each robot in ``targets`` use on ``device``, without training (``wresdyn warmup``): the forward and the
    adjoint variant of its replay solver, each with its step, fused rollout and dynamics-terms kernels, and Newton's
    own kernels that building and stepping a model loads. On CUDA the adjoint is compiled as the one kernel (not the
    pieces a fresh machine starts on; :mod:`~wresdyn.sim.solver_replay.kernels`), in parallel worker processes.

    Args:
        targets: ``(robot file, gains config or None)`` pairs.
        device: Warp device, ``cpu`` or ``cuda:N``.
        rate_hz: Sample rate of the warm-up world [Hz]; the compiled code does not depend on it.
        say: Progress printer (default: ``print``, flushed).
        export: Folder to copy the compiled modules to afterwards, with their index
            (:func:`wresdyn.sim.prebuilt.export`): what a package or container ships so that a fresh machine of the
            same architecture and Warp version loads them instead of compiling.

    Returns:
        The number of cache entries this call added (0: everything was compiled already).
    """
    import os

    import warp as wp

    say = say or (lambda line: print(line, flush=True))
    wp.config.quiet = True  # no banner: the lines below say what happens
    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    wp.init()
    require_device(device)
    dev = wp.get_device(device)
    before = _cache_entries()
    t0 = time.perf_counter()
    given = os.environ.get("WRESDYN_ADJOINT_PIECES")
    if dev.is_cuda and not given:  # the one kernel: what every later run takes once the cache holds it
        os.environ["WRESDYN_ADJOINT_PIECES"] = "0"
    try:
        for path, gains in targets:
            robot = load_robot(path, gains=gains)
            compile_kernels(robot, rate_hz, ("forward", "param_grads"), device=device, say=say)
            sims = [Simulator(robot, 1, 1.0 / rate_hz, device=device, requires_grad=g, param_grads=g)
                    for g in (False, True)]
            t1 = time.perf_counter()
            # a servo robot's commands pass through the goal profile's kernels first
            servo = getattr(sims[0].solver, "servo", None) is not None
            compile_batch(_solver_modules(sims) + (profile_modules() if servo else []), dev)
            # the check every fit runs first: one world stepped under the data's commands, Newton's kernels with it
            check_newton(robot, rate_hz, robot.q0, device=device)
            say(f"... every replay kernel of {Path(str(robot.source)).name} and the check a fit starts with in "
                f"{time.perf_counter() - t1:.1f} s")
    finally:
        if dev.is_cuda and not given:
            os.environ.pop("WRESDYN_ADJOINT_PIECES", None)
    added = len(_cache_entries() - before)
    say(f"warmup: {added} new entries in {_home(str(wp.config.kernel_cache_dir))} in "
        f"{time.perf_counter() - t0:.1f} s" + ("" if added else " (all compiled already)"))
    if export is not None:
        names = export_prebuilt(dev, export)
        say(f"exported {len(names)} compiled modules for {dev} to {export} (Warp {wp.config.version}): used by a "
            f"fresh machine of the same architecture and Warp version given WRESDYN_PREBUILT_KERNELS={export}")
    return added
