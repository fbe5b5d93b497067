"""Drive saturation on the "real" robot while a floor skill stands on one foot: redeploy a ``wresdyn deploy --floor``
run's policies on its held-out stepping and kick motions and print, per policy, the four joints whose drive torque
sat at the real robot's torque limit for the largest share of physics substeps (over the motions still running).

    python benchmarks/skills/floor_saturation.py RUN [--data DATASET]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("run")
    p.add_argument("--data", default=None, help="the dataset whose mismatch is the real robot (default: shipped)")
    args = p.parse_args()

    import torch

    from floor_run import held_out
    from wresdyn.skills.env import TrackingEnv
    from wresdyn.skills.plants import RealPlant
    from wresdyn.skills.skill_ppo import load_skill

    torch.set_num_threads(1)
    run = Path(args.run)
    res, task, floating, motions, real = held_out(run, args.data)
    cfg = res["config"]
    names = list(floating.joint_names)
    for family in ("step", "kick"):
        fam = [m for m in motions if m.family == family]
        for name in res["policies"]:
            plant = RealPlant(real, len(fam), task.decimation, seed=cfg["seed"] + 100,
                              imu_noise=(task.gyro_noise, task.gravity_noise))
            env = TrackingEnv(plant, fam, task, random_start=False)
            policy = load_skill(run / "skills" / name)
            obs, alive, share = env.get_observations()["policy"], np.ones(len(fam), bool), []
            limit = np.abs(plant.lim[:, 1])
            with torch.no_grad():
                for _ in range(env.max_episode_length):
                    td, _, done, _ = env.step(policy(obs))
                    obs = td["policy"]
                    if alive.any():  # share of this step's substeps at the limit, per joint
                        share.append((np.abs(plant.tau) >= 0.999 * limit).mean(1)[alive])
                    alive &= ~done.numpy().astype(bool)
            mean = np.concatenate(share).mean(0)
            top = np.argsort(-mean)[:4]
            print(f"{family:5s} {name:15s} saturated substeps: "
                  + ", ".join(f"{names[j]} {100 * mean[j]:.0f} %" for j in top), flush=True)


if __name__ == "__main__":
    main()
