"""A balance skill trained with and without the calibrated robot, deployed zero-shot on the "real" robot's floor.

The calibrated robot is identified **on the stand** (``wresdyn fit`` on the shipped recordings); the skill runs on
the floor, where the humanoid must keep its balance on its own feet. The library pieces of ``wresdyn deploy --floor``
for two policies: floor motions drawn from keyframes (:mod:`wresdyn.skills.motions`), a tracking policy that
sees joints, its IMU and the reference (PPO, rsl-rl, asymmetric actor-critic) trained in the nominal simulator on a
floor, the same policy fine-tuned in the calibrated robot on the floor, and both deployed on the real robot (MuJoCo
C with the dataset's mismatch, standing on its floor):

    wresdyn fit data/dataset.npz --out runs/fit                  # the calibrated robot, on the stand (~2 min)
    python examples/skill_on_the_floor.py runs/fit --out runs/floor_example

prints success, falls, MPJPE and g-MPJPE of the reference played open loop, (a) and (b) on held-out motions.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run", help="a hybrid `wresdyn fit` run folder (physics.json + policy.pt)")
    p.add_argument("--data", default=None, help="dataset whose real robot to deploy on (default: the shipped one)")
    p.add_argument("--out", default="runs/floor_example", help="run folders of the two policies")
    p.add_argument("--iterations", type=int, default=300, help="PPO iterations in the nominal simulator")
    p.add_argument("--finetune", type=int, default=100, help="PPO iterations of the fine-tuning")
    p.add_argument("--envs", type=int, default=64)
    p.add_argument("--motions", type=int, default=3, help="training motions per family")
    p.add_argument("--duration", type=float, default=4.0, help="length of a motion [s]")
    p.add_argument("--no-screen", action="store_true",
                   help="keep every motion as drawn (motions too short for the flat soles to carry)")
    args = p.parse_args()

    from dataclasses import replace

    from wresdyn.data.dataset import load_dataset
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.paths import DEFAULT_DATASET
    from wresdyn.robot.description import load_robot
    from wresdyn.skills.env import SkillTaskConfig, TrackingEnv
    from wresdyn.skills.evaluate import deploy, metrics
    from wresdyn.skills.motions import make_motions
    from wresdyn.skills.plants import RealPlant, sim_plant
    from wresdyn.skills.skill_ppo import SkillPPOConfig, load_skill, train_skill

    ds = load_dataset(args.data or DEFAULT_DATASET)
    stand, floor = load_robot(ds.robot_file), load_robot(ds.robot_file, base="floating")
    task, ppo = SkillTaskConfig.floor(), SkillPPOConfig()  # the worlds are the plants' (args.envs)
    motions = make_motions(stand, {"train": args.motions, "heldout": 1}, args.duration, ds.rate_hz, floating=floor,
                           screen=not args.no_screen)
    out = Path(args.out)

    # (a) the nominal simulator on a floor, (b) (a) fine-tuned in the calibrated robot (identified on the stand)
    nominal = sim_plant("nominal", floor, args.envs, ds.rate_hz, task.decimation, ground=True)
    train_skill(TrackingEnv(nominal, motions["train"], task), replace(ppo, iterations=args.iterations),
                out / "a_nominal")
    calibrated = sim_plant("calibrated", floor, args.envs, ds.rate_hz, task.decimation, args.run, ground=True)
    train_skill(TrackingEnv(calibrated, motions["train"], task, seed=1), replace(ppo, iterations=args.finetune),
                out / "b_calibrated", init=out / "a_nominal")

    # zero-shot on the real robot's floor: the robot the data was recorded on, with its IMU noise
    real = RealRobot(floor, Mismatch.from_dict(ds.mismatch), ds.rate_hz)
    held = motions["heldout"]
    print(f"{'policy':14s} {'success':>8s} {'falls':>6s} {'MPJPE [mrad]':>13s} {'g-MPJPE [mm]':>13s}")
    for name in ("reference", "a_nominal", "b_calibrated"):
        policy = None if name == "reference" else load_skill(out / name)
        plant = RealPlant(real, len(held), task.decimation, imu_noise=(task.gyro_noise, task.gravity_noise))
        m = metrics(deploy(policy, plant, held, task))["mean"]
        print(f"{name:14s} {100 * m['success']:7.0f}% {m['falls']:6d} {1e3 * m['mpjpe']:13.1f} "
              f"{1e3 * m['g_mpjpe']:13.0f}")


if __name__ == "__main__":
    main()
