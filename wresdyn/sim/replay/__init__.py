"""Replay solver: a Newton ``SolverBase`` specialised for PD replay of fixed-base robots (issue 6).

:class:`SolverReplay` runs each step as one generated, differentiable Warp kernel (one thread per
world); :mod:`.tree` reads the robot from a Newton model, :mod:`.codegen` writes the kernels,
:mod:`.replay` is the solver.
"""

from .solver import SolverReplay
from .tree import ReplayTree, TreeError

__all__ = ["ReplayTree", "SolverReplay", "TreeError"]
