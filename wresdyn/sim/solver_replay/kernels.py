"""Which kernels a :class:`~.solver.SolverReplay` runs, and when they compile.

A robot's kernels are generated once per process (:func:`load_kernels`) and compiled by Warp into its cache. On CUDA
the adjoint comes in two forms: one kernel, which NVRTC compiles for the humanoid in 76 CPU-seconds (the first GPU
run's wait), and a chain of pieces (:mod:`.split`), which compile side by side in a fraction of that and run
1.3-1.5x slower. :func:`choose_pieces` takes the one kernel where Warp's cache holds it, else the pieces, and
compiles the one kernel in a detached worker process for the next run. :func:`deferred_compile` lets a caller building
several solvers (a command's variants) compile all their modules in one parallel batch.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp

from ...errors import WresdynError
from ..prebuilt import fetch
from .cache import load_module
from .codegen import generate_source
from .tree import ReplayTree

__all__ = ["ADJOINT_PIECES", "BLOCK_DIM", "FAST_MATH", "LANES", "LANE_WARP", "SMEM_SPILL", "background_compiles",
           "branch_lanes", "choose_pieces", "compile_batch", "compile_now", "compile_in_processes", "cuda_launch",
           "deferred_compile", "deferring", "lane_width", "load_kernels", "start_background_compiles"]


def load_kernels(tree: ReplayTree, scalar: str, backward: bool, cuda: bool, friction_sweeps: int,
                  servo: np.ndarray | None = None, pieces: int = 0):
    """Generate and load (:func:`~.cache.load_module`) the kernel module for ``tree``.

    The step kernel's adjoint is outlined into non-inlined functions for Clang (CPU), where the whole step
    as one function compiled for two minutes (16 s outlined); NVRTC is the other way round: the humanoid's
    adjoint compiles for sm_90 in 76 CPU-seconds force-inlined (as without a hint: NVRTC then inlines the
    chunks itself), while out-of-line chunks keep its front end busy past 760 CPU-seconds
    (``benchmarks/results/compile/cuda_probe_cpu.txt``), so CUDA inlines. ``pieces`` > 0: the adjoint as a chain
    of kernels of about that many statements (:mod:`.split`), which NVRTC compiles side by side.
    """
    servo = None if servo is None or not np.asarray(servo).any() else np.asarray(servo, dtype=bool)
    pieces = int(pieces) if backward else 0
    block_dim, spill, fast = cuda_launch() if cuda else (None, False, False)
    lanes = branch_lanes(cuda)
    key = (tree.digest(), scalar, bool(backward), bool(cuda), int(friction_sweeps),
           None if servo is None else servo.tobytes(), pieces, block_dim, spill, fast, lanes)
    if key not in _SOURCES:  # a robot's solvers are built many times a process; its source depends on the key only
        _SOURCES[key] = generate_source(tree, scalar, backward, inline=bool(cuda), friction_sweeps=friction_sweeps,
                                        servo=servo, pieces=pieces or None, block_dim=block_dim, smem_spill=spill,
                                        fast_math=fast, lanes=lanes)
    mod = load_module(_SOURCES[key])
    for k in (mod.replay_step, mod.replay_rollout, mod.replay_terms, *getattr(mod, "PIECES", ())):
        _JOBS[id(k.module)] = (mod.__file__, k.func.__name__)
    return mod


BLOCK_DIM = 32
"""Threads per CUDA block of the replay kernels (``$WRESDYN_REPLAY_BLOCK_DIM`` overrides it). A world is one long
serial thread, so a block of Warp's default 256 puts 1024 worlds on 4 of the GPU's ~132 multiprocessors; blocks of 32
spread them over 32. On an H200 at 1024 worlds the adjoint step takes 0.19 ms against 0.34 ms, the forward 0.04
against 0.07; at 16384 worlds the replay runs within -2 to +6 % of it. Blocks of 64 run 4-10 % behind 32 at 1024
worlds and within 1 % of it at 16384 (``benchmarks/results/speed_paths/block_dim/``)."""

SMEM_SPILL = False
"""Let the replay kernels spill registers to shared memory (``$WRESDYN_REPLAY_SMEM_SPILL`` 0/1 overrides it; CUDA 13
toolkits). Off: on an H200 it slowed the adjoint at blocks of 32 from 0.19 to 0.23 ms a step."""

FAST_MATH = False
"""Compile the replay kernels with fast math (``$WRESDYN_REPLAY_FAST_MATH`` 0/1 overrides it). Off: on an H200 it saved
2 % of the adjoint step and moved the gradient fit's result (validation 0.0314 against 0.0311 rad)."""


LANES = True
"""On CUDA, step a world's branches from the fixed base in threads of their own (:func:`.codegen._lanes`;
``$WRESDYN_REPLAY_LANES`` 0/1 overrides it on any device). The CPU runs a kernel's threads one after another, so
there they would only add loads: off unless the variable asks."""


def branch_lanes(cuda: bool) -> bool:
    """Whether the replay kernels (step, rollout, the adjoint's pieces) run one thread per world and branch of the base
    (:data:`LANES`, ``$WRESDYN_REPLAY_LANES``)."""
    return _env_flag("WRESDYN_REPLAY_LANES", LANES and bool(cuda))


LANE_WARP = 32
"""On CUDA a laned kernel's threads per branch are its worlds rounded up to a multiple of this (a warp), the threads
past the last world returning at once: a warp then runs one branch's code. Unpadded, a batch of 8 worlds puts the
humanoid's three branches in one warp, which runs them one after another: on an H100 an online update's adjoint
kernels are busy 99.6 ms against 44.7 padded (``benchmarks/results/speed_paths/lane_warps/``)."""


def lane_width(worlds: int, cuda: bool) -> int:
    """Threads per branch of a laned launch of ``worlds`` worlds: on CUDA rounded up to :data:`LANE_WARP`; on the CPU,
    where a kernel's threads run one after another, ``worlds``."""
    return -(-worlds // LANE_WARP) * LANE_WARP if cuda else worlds


def _env_flag(name: str, default: bool) -> bool:
    """The environment variable ``name`` as 0 or 1, ``default`` where unset or empty."""
    raw = os.environ.get(name, "").strip()
    if raw not in ("", "0", "1"):
        raise WresdynError(f"{name}={raw!r}: give 0 or 1")
    return raw == "1" if raw else default


def cuda_launch() -> tuple[int, bool, bool]:
    """(threads per block, shared-memory spilling, fast math) of the CUDA replay kernels: :data:`BLOCK_DIM`,
    :data:`SMEM_SPILL`, :data:`FAST_MATH`, or where set ``$WRESDYN_REPLAY_BLOCK_DIM``, ``_SMEM_SPILL``,
    ``_FAST_MATH``."""
    raw = os.environ.get("WRESDYN_REPLAY_BLOCK_DIM", "").strip()
    block = BLOCK_DIM
    if raw:
        block = int(raw) if raw.isdigit() else 0
        if not 1 <= block <= 1024:
            raise WresdynError(f"WRESDYN_REPLAY_BLOCK_DIM={raw!r}: give threads per block, 1 to 1024")
    return (block, _env_flag("WRESDYN_REPLAY_SMEM_SPILL", SMEM_SPILL),
            _env_flag("WRESDYN_REPLAY_FAST_MATH", FAST_MATH))


_JOBS: dict[int, tuple[str, str]] = {}
"""Warp module id -> (its generated file, its kernel's name): what a worker process needs to compile it."""


_SOURCES: dict[tuple, str] = {}
"""Generated kernel sources of this process by (tree digest, scalar, backward, cuda, friction sweeps, servo DoFs,
adjoint pieces, CUDA block size, shared-memory spilling, fast math, branch lanes)."""

ADJOINT_PIECES = 400
"""Statements per adjoint kernel on CUDA while the one-kernel adjoint is not compiled
(``SolverReplay(adjoint_pieces=)``): the humanoid's adjoint as one kernel takes NVRTC 76 CPU-seconds for sm_90,
its 12 pieces of this size 0.5-5 s each (35 in all, side by side); the pieces run 1.3-1.5x slower
(``benchmarks/results/first_fit/h100_pieces/``). In lanes (:data:`LANES`) a kernel holds a piece of about this many
statements over the lanes together: the humanoid's 13 kernels take 0.5-7.9 CPU-seconds each, and a fresh H200's first
default fit 110 s against 130 with the pieces one thread per world (``benchmarks/results/first_fit/h200_lanes/``)."""

_BACKGROUND: dict[str, object] = {}
"""Background compiles of one-kernel adjoint modules this process started, by Warp module identifier: a detached
worker process (:class:`subprocess.Popen`) or, where Warp's cache layout is not 1.19's, a thread."""


def background_compiles() -> list[str]:
    """Identifiers of the one-kernel adjoint modules still compiling in the background (:class:`SolverReplay`)."""
    return [k for k, w in _BACKGROUND.items() if (w.poll() is None if hasattr(w, "poll") else w.is_alive())]


_PENDING: list[tuple] = []
"""(module, device) to compile in the background once :func:`deferred_compile`'s caller has compiled its batch."""


def start_background_compiles() -> None:
    """Start the background compiles the solvers built under :func:`deferred_compile` asked for (after the batch:
    started earlier they compete with it for the cores)."""
    while _PENDING:
        _compile_later(*_PENDING.pop(0))


def _compile_later(module, device) -> None:
    """Compile ``module`` into Warp's kernel cache in the background, once per process, for the next run: a worker
    process (:mod:`.compile_worker`) in a session of its own, which outlives the command, so that a short command
    neither waits for it at exit nor kills it (Warp builds into a temporary folder and renames it: a cache entry is
    whole or absent). Where Warp's cache layout is not 1.19's, a thread the command waits for at exit instead. A
    failure only leaves the pieces in use. Under :func:`deferred_compile`: listed for
    :func:`start_background_compiles`."""
    key = module.get_module_identifier()
    if key in _BACKGROUND or any(m is module for m, _ in _PENDING):
        return
    if _DEFERRED is not None:
        _PENDING.append((module, device))
        return
    ptx = _ptx(module, device)
    if ptx is not None and id(module) in _JOBS:
        _BACKGROUND[key] = subprocess.Popen(_worker_args(module, device.arch, ptx), env=_worker_env(),
                                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                            stderr=subprocess.DEVNULL, start_new_session=True)
        return

    def work():
        try:
            wp.compile_aot_module(module, device=device)
        except Exception:  # noqa: BLE001 - the pieces serve; the next run tries again
            pass

    _BACKGROUND[key] = threading.Thread(target=work, name="wresdyn-adjoint-compile")
    _BACKGROUND[key].start()


def _pieces_from_env() -> int | None:
    """``$WRESDYN_ADJOINT_PIECES`` as a number of statements (0: one kernel), None where unset or empty."""
    raw = os.environ.get("WRESDYN_ADJOINT_PIECES", "").strip()
    if not raw:
        return None
    try:
        value = int(raw)
    except ValueError:
        value = -1
    if value < 0:
        raise WresdynError(f"WRESDYN_ADJOINT_PIECES={raw!r}: give a number of statements >= 0 (0: one kernel)")
    return value


def _compiled(module, device) -> bool:
    """Whether Warp's kernel cache holds ``module``'s binary for ``device`` (Warp 1.19's cache layout; False if
    that cannot be told), after copying it in from the prebuilt kernels where they hold it exactly
    (:func:`~wresdyn.sim.prebuilt.fetch`)."""
    try:
        fetch(module, device)
        name = module._get_compile_output_name(device)
        return os.path.exists(os.path.join(wp.config.kernel_cache_dir, module.get_module_identifier(), name))
    except (AttributeError, TypeError, OSError):
        return False


_DEFERRED: list | None = None
"""While :func:`deferred_compile` runs: the CUDA modules solvers built meanwhile would have compiled."""


def deferring() -> bool:
    """Whether :func:`deferred_compile` is in force (solvers built now compile nothing, not even at construction)."""
    return _DEFERRED is not None


@contextlib.contextmanager
def deferred_compile():
    """Within: CUDA solvers leave their modules uncompiled and list them in the yielded list instead, so that a caller
    building several (a command's variants) compiles them all in one batch (:func:`compile_batch`)."""
    global _DEFERRED
    outer, _DEFERRED = _DEFERRED, [] if _DEFERRED is None else _DEFERRED
    try:
        yield _DEFERRED
    finally:
        _DEFERRED = outer


def choose_pieces(tree: ReplayTree, scalar: str, backward: bool, device, friction_sweeps: int,
                  servo: np.ndarray | None, pieces: int | None) -> tuple[int, object]:
    """Statements per adjoint kernel for a solver, and the one-kernel adjoint module to compile in the background
    (or None). ``pieces`` as given to the solver; None: ``$WRESDYN_ADJOINT_PIECES`` where set, else on CUDA the
    one kernel where Warp's cache holds it and :data:`ADJOINT_PIECES` otherwise, on the CPU the one kernel."""
    if pieces is None:
        pieces = _pieces_from_env()
    later = None
    if pieces is None and device.is_cuda and backward and ADJOINT_PIECES:
        whole = load_kernels(tree, scalar, True, True, friction_sweeps, servo, 0).replay_step.module
        pieces = 0 if _compiled(whole, device) else ADJOINT_PIECES
        later = whole if pieces else None
    return (int(pieces or 0) if backward else 0), later


def compile_now(kernels, device, later) -> None:
    """On CUDA: compile ``kernels``' step, rollout and adjoint modules side by side (or list them for the caller of
    :func:`deferred_compile`), then ``later`` (a module or None) in the background."""
    if not device.is_cuda:
        return
    mods = [x.module for x in (kernels.replay_step, kernels.replay_rollout, kernels.replay_terms,
                               *getattr(kernels, "PIECES", ()))]
    if _DEFERRED is not None:
        _DEFERRED.extend(m for m in mods if m not in _DEFERRED)
    else:
        compile_batch(mods, device)
    if later is not None:
        _compile_later(later, device)


def compile_batch(mods: list, device) -> None:
    """Compile and load Warp modules side by side: on CUDA the generated ones not yet in Warp's cache first in worker
    processes (:mod:`.compile_worker`; NVRTC in threads of one process slows each compile down several times), then
    every module in this process's threads, which load what the workers wrote. A worker that fails leaves its module
    to the in-process load, which compiles it."""
    todo = [m for m in mods if device.is_cuda and id(m) in _JOBS and not _compiled(m, device)]
    ptx = _ptx(todo[0], device) if len(todo) > 1 else None
    if ptx is not None:  # not Warp 1.19's layout: the in-process load compiles them
        compile_in_processes(todo, device.arch, ptx)
    wp.force_load(device=device, modules=mods, max_workers=min(len(mods), os.cpu_count() or 1))


def _ptx(module, device) -> bool | None:
    """Whether Warp 1.19 writes ``module`` for ``device`` as PTX (else CUBIN); None where its layout is another."""
    try:
        return module._get_compile_output_name(device).endswith(".ptx")
    except (AttributeError, TypeError):
        return None


def _worker_env() -> dict:
    """A compile worker's environment: NVRTC needs no GPU, so none is visible (no CUDA context per worker)."""
    return dict(os.environ, CUDA_VISIBLE_DEVICES="")


def _worker_args(module, arch: int, ptx: bool) -> list[str]:
    """The command line of a compile worker (:mod:`.compile_worker`) for a generated ``module``."""
    path, name = _JOBS[id(module)]
    worker = os.path.join(os.path.dirname(os.path.abspath(__file__)), "compile_worker.py")
    return [sys.executable, worker, path, name, str(arch), "1" if ptx else "0", str(wp.config.kernel_cache_dir)]


def compile_in_processes(mods: list, arch: int, ptx: bool) -> None:
    """Compile generated modules (made by :func:`load_kernels`) for CUDA architecture ``arch`` (PTX or CUBIN) into
    Warp's kernel cache, one worker process each, as many at once as there are cores; no GPU needed."""
    def run(m):
        subprocess.run(_worker_args(m, arch, ptx), env=_worker_env(), stdin=subprocess.DEVNULL,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)

    with ThreadPoolExecutor(max_workers=min(len(mods), os.cpu_count() or 1)) as pool:
        list(pool.map(run, mods))
