"""``wresdyn demo``: the main job on the embedded defaults, end to end on a 2-core CPU in about 10 minutes
(the pipeline: :mod:`wresdyn.experiments.demo_pipeline`)."""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="runs/demo", help="output folder (default: runs/demo)")
    p.add_argument("--collect", action="store_true", help="record a fresh small dataset instead of the shipped one")
    p.add_argument("--ppo-iterations", type=int, default=300,
                   help="PPO iterations of the residual (0.3-0.5 s each on 2 CPU cores)")
    p.add_argument("--skill-iterations", type=int, default=200,
                   help="PPO iterations of the skill in the nominal simulator, and of each fine-tuning")
    p.add_argument("--quick", action="store_true", help="tiny sizes: a smoke run of a minute")


def run(args: argparse.Namespace) -> int:
    from ..experiments.demo_pipeline import run_demo

    run_demo(args.out, collect=args.collect, ppo_iterations=args.ppo_iterations,
             skill_iterations=args.skill_iterations, quick=args.quick)
    return 0
