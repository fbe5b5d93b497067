"""``wresdyn`` with the replay solver's damper dry-friction law of rate KAPPA [1/s] in place of its soft default, for
every simulation the command runs (an identification's training, its selection on validation and ``--eval`` alike).

An experiment, not an option of the project: the soft law (MuJoCo's ``frictionloss``) creeps under any load below its
bound, which a servo that rests under gravity cannot (docs/results/real-data.md, "What stands in the way").

    OMP_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python benchmarks/identify_friction_law.py KAPPA identify DATA ...
"""

import sys

if __name__ == "__main__":
    import wresdyn.sim.solver_replay as solver_replay
    from wresdyn.cli import main

    kappa = float(sys.argv[1])
    default = solver_replay.SolverReplay
    # the simulator builds its solver from this name (wresdyn.sim.solvers)
    solver_replay.SolverReplay = lambda model, **kw: default(model, friction_kappa=kappa, **kw)
    sys.exit(main(sys.argv[2:]))
