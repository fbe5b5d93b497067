"""Stage 3, the simulation: Newton replay of recorded commands under PD plus a residual.

:mod:`.solvers` picks the Newton solver, :mod:`.replay` is SolverReplay (this project's fused, differentiable
Newton solver for the replay workload), :mod:`.parity` checks Newton against MuJoCo C, :mod:`.bench` times it.
"""
