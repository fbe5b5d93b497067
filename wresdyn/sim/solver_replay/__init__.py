"""Replay solver: a Newton ``SolverBase`` specialised for PD replay of fixed-base robots.

:class:`SolverReplay` runs each step as one generated, differentiable Warp kernel (one thread per world; on CUDA
one per world and branch of the robot's base). In data-flow order: :mod:`.tree` reads the robot from a Newton model,
:mod:`.emit` writes straight-line code, :mod:`.dynamics` generates the rigid-body algorithms and :mod:`.codegen` the
step kernels around them (:mod:`.split` cuts the adjoint into a chain of smaller kernels for NVRTC), :mod:`.cache`
stores and loads the generated modules, :mod:`.kernels` chooses a solver's kernels and when they compile,
:mod:`.solver` is the solver and :mod:`.launch` calls its recorded launches directly on the CPU.
"""

from .cache import KernelCacheError, kernel_dir
from .solver import FRICTION_KAPPA, FRICTION_SWEEPS, SolverReplay
from .tree import ReplayTree, TreeError

__all__ = ["FRICTION_KAPPA", "FRICTION_SWEEPS", "KernelCacheError", "ReplayTree", "SolverReplay", "TreeError",
           "kernel_dir"]
