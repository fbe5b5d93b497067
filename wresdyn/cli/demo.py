"""``wresdyn demo``: the main job on the embedded defaults, end to end on a 2-core CPU in about 10 minutes
(the pipeline: :mod:`wresdyn.experiments.demo_pipeline`)."""

from __future__ import annotations

from dataclasses import dataclass

from .command import Command


@dataclass(frozen=True)
class Demo(Command):
    """``wresdyn demo``: where, and how long."""

    out: str = "runs/demo"
    """Output folder."""
    collect: bool = False
    """Record a fresh small dataset instead of the shipped one."""
    ppo_iterations: int = 300
    """PPO iterations of the residual (0.3-0.5 s each on 2 CPU cores)."""
    skill_iterations: int = 200
    """PPO iterations of the skill in the nominal simulator, and of each fine-tuning."""
    quick: bool = False
    """Tiny sizes (the first 2 s of one trajectory per split, two for training; a few iterations each): a smoke
    run of a minute."""


COMMAND = Demo


def run(args: Demo) -> int:
    from ..experiments.demo_pipeline import run_demo

    run_demo(args.out, collect=args.collect, ppo_iterations=args.ppo_iterations,
             skill_iterations=args.skill_iterations, quick=args.quick)
    return 0
