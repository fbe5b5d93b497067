"""``wresdyn bench``: env-steps/s of the replay workload for every solver, same robot, same worlds.

The benchmark itself is :mod:`wresdyn.sim.solver_benchmark` (its docstring lists the rows and the method).
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from typing import Literal

from .command import Command

BenchSolver = Literal["replay", "featherstone", "mujoco-warp", "mujoco-c"]  # solver_benchmark.SOLVERS, no warp


@dataclass(frozen=True)
class Bench(Command):
    """``wresdyn bench``: the robot, the world counts and how long to measure."""

    robot: str | None = None
    """Robot file (default: the project humanoid)."""
    gains: str | None = None
    """Gains override TOML (see wresdyn.robot.gains.apply_overrides)."""
    worlds: tuple[int, ...] = ()
    """World counts (empty: 1 16 128 on CPU; 1024 4096 16384 on CUDA)."""
    device: str = "cpu"
    """Warp device: cpu or cuda:0."""
    steps: int = 200
    """Steps per forward measurement."""
    horizon: int = 32
    """Tape horizon H of the forward+backward measurement."""
    slow_steps: int = 16
    """Steps per forward call for SolverFeatherstone (it is slow)."""
    slow_max_worlds: int = 4096
    """Skip SolverFeatherstone forward+backward above this many worlds (minutes per measurement)."""
    threads: int = 2
    """CPU threads for the replay rollout and MuJoCo C."""
    solvers: tuple[BenchSolver, ...] = ("replay", "featherstone", "mujoco-warp", "mujoco-c")
    """Solvers to measure."""
    dt: float = 0.002
    """Time step [s]."""
    min_time: float = 0.5
    """Seconds to time each measurement for (after a warm-up)."""
    adjoint: Literal["auto", "one", "pieces"] = "auto"
    """SolverReplay's adjoint in the forward+backward rows: auto, the form a fit takes on this machine now (on CUDA the
    one kernel once Warp's cache holds it, the pieces until then); one: the one kernel (compiled first if need be);
    pieces: the chain of smaller kernels a fresh machine starts on."""
    json: str | None = None
    """Also write the results to this JSON file."""


COMMAND = Bench


def run(args: Bench) -> int:
    from ..sim.solver_benchmark import run_bench

    from types import SimpleNamespace

    # the benchmark reads its world counts as the comma list of old, its solvers as a list
    given = {f.name: getattr(args, f.name) for f in fields(args)}
    return run_bench(SimpleNamespace(**given | {"worlds": ",".join(map(str, args.worlds)) or None,
                                                "solvers": list(args.solvers)}))
