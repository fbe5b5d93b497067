"""PPO vs gradient: learn the same residual torque two ways on the shipped data and compare.

    python examples/ppo_vs_gradient.py            # a few minutes on a 2-core CPU
    python examples/ppo_vs_gradient.py --test     # a smoke run of seconds

PPO (rsl-rl, the paper's Table I rewards) explores residual torques and scores them; the gradient fit
backpropagates the joint-state mismatch through the differentiable Warp simulation. Both train the same
MLP on the same training trajectories and are evaluated identically: open-loop replay of each held-out
trajectory from its first recorded state. The full grid (MLP/GRU, torque/delta action, seeds, the
parametric baseline) is ``wresdyn ablate``.
"""

import argparse
import dataclasses

import wresdyn
from wresdyn.data.dataset import load_dataset
from wresdyn.experiments.ablation import AblationConfig, run_ablation
from wresdyn.paths import DEFAULT_DATASET


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--test", action="store_true", help="tiny sizes, for CI")
    parser.add_argument("--out", default="runs/ppo_vs_gradient")
    args = parser.parse_args()

    robot = wresdyn.load_robot(wresdyn.DEFAULT_ROBOT)
    data = load_dataset(DEFAULT_DATASET, robot=robot)
    cfg = AblationConfig(learners=("ppo", "gradient"), archs=("mlp",), kinds=("torque",), seeds=(0,),
                         ppo_iterations=100, gradient_iterations=1000, segments=4)
    if args.test:
        heldout = data.split("heldout")[:1]
        data = dataclasses.replace(data, trajectories=data.split("train")[:2] + heldout + data.split("ood")[:1])
        cfg = dataclasses.replace(cfg, ppo_iterations=2, gradient_iterations=4, segments=2,
                                  ppo_overrides={"env.num_worlds": 8, "ppo.num_steps_per_env": 8},
                                  gradient_overrides={"windows": 4, "horizon": 4, "horizon_curriculum": ()})
    run_ablation(robot, data, cfg, args.out)
    print(open(f"{args.out}/table.md").read())
    print(f"learning curves: {args.out}/curves.png")


if __name__ == "__main__":
    main()
