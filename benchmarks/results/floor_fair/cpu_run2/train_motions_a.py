"""(a) (the shipped ``floor_nominal``) and the open-loop reference deployed on the real robot's floor over the CPU
run's TRAINING motions (the ones the fine-tunings train on): does the real robot make (a) fail on them, i.e. do the
fine-tunings see the failures that the validation motions show?

    PYTHONPATH=$PWD OMP_NUM_THREADS=1 python benchmarks/results/floor_fair/cpu_run2/train_motions_a.py [SKILL_RUN ...]
"""

from __future__ import annotations

import sys
from pathlib import Path

import torch

from wresdyn.data.loading import load_data
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.experiments.deploy_config import FloorDeployConfig
from wresdyn.robot import load_robot
from wresdyn.skills.evaluate import deploy, metrics
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import RealPlant
from wresdyn.skills.shipped import shipped_folder
from wresdyn.skills.skill_config import FloorTaskConfig
from wresdyn.skills.skill_ppo import load_skill

ROOT = Path(__file__).resolve().parents[4]
torch.set_num_threads(2)
ds, robot = load_data(str(ROOT / "data" / "dataset.npz"))
mismatch = Mismatch.load(str(ROOT / "data" / "mismatch_default.toml"))
cfg, task = FloorDeployConfig(), FloorTaskConfig()
floating = load_robot(robot.source, gains=robot.gains, base="floating")
rate = float(ds.rate_hz)
motions = make_motions(robot, {"train": cfg.train_per_family, "validation": cfg.validation_per_family},
                       cfg.duration, rate, cfg.seed, floating=floating, screen=cfg.screen)
train = motions.split("train")
real = RealRobot(floating, mismatch, rate)
for name in ["reference", str(shipped_folder("floor_nominal")), *sys.argv[1:]]:
    policy = None if name == "reference" else load_skill(name)
    plant = RealPlant(real, len(train), task.decimation, seed=cfg.seed + 100,
                      imu_noise=(task.gyro_noise, task.gravity_noise))
    m = metrics(deploy(policy, plant, train, task), robot)
    per = " ".join(f"{mo.name.removeprefix('train_')}:{'ok' if r['success'] else r['cause']}"
                   for mo, r in zip(train, m["motions"]))
    print(f"TRAIN {name}: success {m['mean']['success'] * len(train):.0f}/{len(train)} falls {m['mean']['falls']} "
          f"MPJPE {1e3 * m['mean']['mpjpe']:.1f} mrad | {per}", flush=True)
