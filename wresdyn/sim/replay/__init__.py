"""Replay solver: a Newton ``SolverBase`` specialised for PD replay of fixed-base robots (issue 6).

:class:`SolverReplay` runs each step as one generated, differentiable Warp kernel (one thread per
world); :mod:`.tree` reads the robot from a Newton model, :mod:`.codegen` writes the kernels,
:mod:`.cache` stores and loads the generated modules, :mod:`.solver` is the solver.
"""

from .cache import KernelCacheError, kernel_dir
from .solver import SolverReplay
from .tree import ReplayTree, TreeError

__all__ = ["KernelCacheError", "ReplayTree", "SolverReplay", "TreeError", "kernel_dir"]
