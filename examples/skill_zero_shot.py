"""A skill trained with and without the calibrated robot, deployed zero-shot on the "real" robot.

The library pieces of ``wresdyn deploy`` for two policies: reference motions drawn from keyframes
(:mod:`wresdyn.skills.motions`), a tracking policy trained by PPO (rsl-rl) in the nominal simulator, the same policy
fine-tuned in the simulator corrected by a ``wresdyn fit`` run (identified physics + residual torque), and both
deployed on the real robot the data was recorded on (MuJoCo C with the dataset's mismatch):

    wresdyn fit data/dataset.npz --out runs/fit                  # the calibrated robot (~2 min)
    python examples/skill_zero_shot.py runs/fit --out runs/skill_example

prints MPJPE, foot error and success of the reference played open loop, (a) and (b) on held-out motions.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", help="a hybrid `wresdyn fit` run folder (physics.json + policy.pt)")
    p.add_argument("--data", default=None, help="dataset whose real robot to deploy on (default: the shipped one)")
    p.add_argument("--out", default="runs/skill_example", help="run folders of the two policies")
    p.add_argument("--iterations", type=int, default=300, help="PPO iterations in the nominal simulator")
    p.add_argument("--finetune", type=int, default=300, help="PPO iterations of the fine-tuning")
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--motions", type=int, default=4, help="training motions per family")
    args = p.parse_args()

    from dataclasses import replace

    from wresdyn.data.dataset import load_dataset
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.paths import DEFAULT_DATASET
    from wresdyn.robot.description import load_robot
    from wresdyn.skills.env import SkillConfig, TrackingEnv
    from wresdyn.skills.evaluate import deploy, metrics
    from wresdyn.skills.motions import make_motions
    from wresdyn.skills.plants import RealPlant, sim_plant
    from wresdyn.skills.skill_ppo import SkillPPOConfig, load_skill, train_skill

    ds = load_dataset(args.data or DEFAULT_DATASET)
    robot = load_robot(ds.robot_file)
    task = SkillConfig()
    ppo = SkillPPOConfig()  # the worlds are the plants' (args.envs)
    motions = make_motions(robot, {"train": args.motions, "heldout": 1}, duration=2.0, rate_hz=ds.rate_hz)
    out = Path(args.out)

    # (a) the nominal simulator, (b) (a) fine-tuned in the calibrated one
    nominal = sim_plant("nominal", robot, args.envs, ds.rate_hz, task.decimation)
    train_skill(TrackingEnv(nominal, motions.split("train"), task), replace(ppo, iterations=args.iterations),
                out / "a_nominal")
    calibrated = sim_plant("calibrated", robot, args.envs, ds.rate_hz, task.decimation, args.run)
    train_skill(TrackingEnv(calibrated, motions.split("train"), task, seed=1), replace(ppo, iterations=args.finetune),
                out / "b_calibrated", init=out / "a_nominal")

    # zero-shot on the real robot: the robot the data was recorded on
    real = RealRobot(robot, Mismatch.from_dict(ds.mismatch), ds.rate_hz)
    held = motions.split("heldout")
    print(f"{'policy':14s} {'MPJPE [mrad]':>13s} {'foot [mm]':>10s} {'success':>8s}")
    for name in ("reference", "a_nominal", "b_calibrated"):
        policy = None if name == "reference" else load_skill(out / name)
        m = metrics(deploy(policy, RealPlant(real, len(held), task.decimation), held, task), robot)["mean"]
        print(f"{name:14s} {1e3 * m['mpjpe']:13.2f} {1e3 * m['foot_error']:10.2f} {100 * m['success']:7.0f}%")


if __name__ == "__main__":
    main()
