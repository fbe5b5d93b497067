"""``wresdyn bench``: env-steps/s of the replay workload for every solver, same robot, same worlds.

The benchmark itself is :mod:`wresdyn.sim.solver_benchmark` (its docstring lists the rows and the method).
"""

from __future__ import annotations

import argparse

_SOLVERS = ("replay", "featherstone", "mujoco-warp", "mujoco-c")  # solver_benchmark.SOLVERS, without importing warp


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", default=None, help="robot file (default: the project humanoid)")
    p.add_argument("--gains", default=None, help="gains override TOML (see wresdyn.robot.gains.apply_overrides)")
    p.add_argument("--worlds", default=None,
                   help="comma list of world counts (default 1,16,128 on CPU; 1024,4096,16384 on CUDA)")
    p.add_argument("--device", default="cpu", help="Warp device: cpu or cuda:0")
    p.add_argument("--steps", type=int, default=200, help="steps per forward measurement")
    p.add_argument("--horizon", type=int, default=32, help="Tape horizon H of the forward+backward measurement")
    p.add_argument("--slow-steps", type=int, default=16,
                   help="steps per forward call for SolverFeatherstone (it is slow)")
    p.add_argument("--slow-max-worlds", type=int, default=4096,
                   help="skip SolverFeatherstone forward+backward above this many worlds (minutes per measurement)")
    p.add_argument("--threads", type=int, default=2, help="CPU threads for the replay rollout and MuJoCo C")
    p.add_argument("--solvers", default=",".join(_SOLVERS), type=_solver_list,
                   help=f"comma list from {','.join(_SOLVERS)}")
    p.add_argument("--dt", type=float, default=0.002, help="time step [s]")
    p.add_argument("--min-time", type=float, default=0.5, help="seconds to time each measurement for (after a warm-up)")
    p.add_argument("--json", default=None, help="also write the results to this JSON file")




def _solver_list(text: str) -> list[str]:
    solvers = [s.strip() for s in text.split(",") if s.strip()]
    unknown = sorted(set(solvers) - set(_SOLVERS))
    if unknown:
        raise argparse.ArgumentTypeError(f"unknown solver(s) {unknown}; choose from {','.join(_SOLVERS)}")
    return solvers


def run(args: argparse.Namespace) -> int:
    from ..sim.solver_benchmark import run_bench

    return run_bench(args)
