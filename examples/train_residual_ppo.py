"""Learn a residual-dynamics policy with PPO and check it open-loop on held-out data (paper Sec. II-B, III).

    python examples/train_residual_ppo.py --data data/dataset.npz     # a dataset from `wresdyn collect`
    python examples/train_residual_ppo.py --test                      # record a tiny one, train briefly (< 1 min)

The same steps as ``wresdyn train`` followed by ``wresdyn eval``, through the library API.
"""

from __future__ import annotations

import argparse
import dataclasses

from wresdyn import load_robot
from wresdyn.evaluation.open_loop import evaluate_split, write_report
from wresdyn.evaluation.plots import plot_fig3
from wresdyn.learn.run_residual import load_policy
from wresdyn.ppo.ppo_config import default_config
from wresdyn.ppo.trainer import train
from wresdyn.robot.description import DEFAULT_ROBOT


def tiny_dataset(robot):
    """Two training, one held-out and one OOD trajectory of 0.5 s on the default mismatched "real" robot."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import collect
    from wresdyn.paths import DEFAULT_MISMATCH

    return collect(robot, Mismatch.load(DEFAULT_MISMATCH), {"train": 2, "validation": 1, "heldout": 1, "ood": 1}, duration=0.5)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--data", help="dataset .npz (wresdyn collect)")
    p.add_argument("--out", default="runs/example_ppo", help="run folder")
    p.add_argument("--arch", default="mlp", choices=("mlp", "gru"))
    p.add_argument("--residual", default="torque", choices=("torque", "delta_action"))
    p.add_argument("--iterations", type=int, default=None)
    p.add_argument("--test", action="store_true", help="tiny dataset and configuration, for a smoke run")
    args = p.parse_args()

    robot = load_robot(DEFAULT_ROBOT)
    if args.test:
        dataset = tiny_dataset(robot)
    else:
        from wresdyn.data.dataset import load_dataset

        dataset = load_dataset(args.data, robot)

    # One config object holds environment, residual, Table I rewards and PPO; copy it, never mutate it.
    cfg = default_config()
    cfg = dataclasses.replace(cfg, residual=dataclasses.replace(cfg.residual, arch=args.arch, kind=args.residual))
    if args.test:
        cfg = dataclasses.replace(
            cfg,
            env=dataclasses.replace(cfg.env, num_worlds=4, horizon=16),
            residual=dataclasses.replace(cfg.residual, hidden_dims=(32, 32), critic_hidden_dims=(32, 32), gru_hidden_dim=32),
            ppo=dataclasses.replace(cfg.ppo, num_steps_per_env=8, iterations=2, save_interval=1),
        )
    if args.iterations:
        cfg = dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, iterations=args.iterations))

    summary = train(dataset, robot, cfg, args.out)  # resumes if args.out holds checkpoints of the same config
    print(f"{summary['env_steps_per_s'] or 0:.0f} env-steps/s, {summary['s_per_iteration'] or 0:.2f} s/iteration")

    policy, meta = load_policy(args.out)  # the exported residual (torch.export): raw [q, qd, qdd, q_cmd] -> N*m or rad
    results = {}
    for split in ("heldout", "ood"):
        trajs = dataset.split(split)
        summary, runs = evaluate_split(robot, trajs, dataset.rate_hz, policy, meta["kind"], cfg.env.solver)
        results[split] = summary
        plot_fig3(robot, trajs[0], runs, f"{args.out}/eval/fig3_{split}.png", dataset.rate_hz)
        print(f"{split}: mean |dq| PD only {summary['pd_only']['mean_abs_dq']:.4f} rad, "
              f"PD + residual {summary['pd_residual']['mean_abs_dq']:.4f} rad")
    print("report:", write_report(f"{args.out}/eval", robot, results, {"run": args.out}))


if __name__ == "__main__":
    main()
