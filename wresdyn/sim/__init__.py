"""The simulation: Newton replay of recorded commands under PD plus a residual, one layer for all.

- :mod:`.simulator`: :class:`Simulator`, N worlds of a robot stepped under PD with a residual (fast and
  differentiable paths, divergence limits, device stream, CUDA graphs);
- :mod:`.bank`: recorded trajectories on the device, cut into :class:`Window` s, with the command delay/hold;
- :mod:`.residual_kinds`: the residual kinds, their authority, observation and application;
- :mod:`.physics`: the simulator's physical parameters (gains, friction, delay, link inertias) as fitted
  quantities, physically consistent, read and written as JSON;
- :mod:`.rollout`: the rollout driver (policy in the loop) and the numpy :func:`replay`, without gradients on CUDA
  captured whole as one CUDA graph (:mod:`.rollout_graph`); :mod:`.fused`: PD-only
  window rollouts in one solver launch, differentiable to the physical parameters (online identification's);
- :mod:`.solvers`: the Newton solver choice; :mod:`.solver_replay`: SolverReplay, this project's fused differentiable
  solver; :mod:`.parity`: Newton vs MuJoCo C; :mod:`.solver_benchmark`: the solver benchmark behind ``wresdyn bench``;
- :mod:`.first_steps`: the cheap check that a model survives its first steps, before ``collect`` and ``fit`` start.
"""

from ..errors import SimulationDiverged
from .bank import TrajectoryBank, Window
from .rollout import Replays, Rollout, replay, replay_trajectories, rollout
from .simulator import DivergenceLimits, Simulator
from .solvers import SOLVERS, explicit_pd_margin, make_solver, resolve_solver

__all__ = ["SOLVERS", "DivergenceLimits", "Rollout", "SimulationDiverged", "Simulator", "TrajectoryBank", "Window",
           "Replays", "explicit_pd_margin", "make_solver", "replay", "replay_trajectories", "resolve_solver", "rollout"]
