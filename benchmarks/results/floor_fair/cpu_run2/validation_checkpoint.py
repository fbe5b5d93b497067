"""Checkpoints of a fine-tuning (``validation_try.py``'s ``OUT/skills/<policy>/model_<it>.pt``) deployed on the real
robot's floor over the VALIDATION motions only, as the deployment plays a finished policy (the actor's mean): what
a shorter fine-tuning of the same configuration would have deployed, without training it again.

    PYTHONPATH=$PWD OMP_NUM_THREADS=1 python benchmarks/results/floor_fair/cpu_run2/validation_checkpoint.py \
        OUT/skills/d_oracle/model_49.pt [more checkpoints]
"""

from __future__ import annotations

import json
import sys
import tempfile
from dataclasses import fields
from pathlib import Path

import torch

from wresdyn.data.loading import load_data
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.experiments.deploy_config import FloorDeployConfig
from wresdyn.ppo.runner import make_runner
from wresdyn.robot import load_robot
from wresdyn.skills.env import TrackingEnv
from wresdyn.skills.evaluate import deploy, metrics
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import RealPlant
from wresdyn.skills.skill_config import FloorTaskConfig, SkillPPOConfig
from wresdyn.skills.skill_ppo import runner_cfg

ROOT = Path(__file__).resolve().parents[4]
torch.set_num_threads(2)
ds, robot = load_data(str(ROOT / "data" / "dataset.npz"))
mismatch = Mismatch.load(str(ROOT / "data" / "mismatch_default.toml"))
cfg, task = FloorDeployConfig(), FloorTaskConfig()
floating = load_robot(robot.source, gains=robot.gains, base="floating")
rate = float(ds.rate_hz)
motions = make_motions(robot, {"train": cfg.train_per_family, "validation": cfg.validation_per_family},
                       cfg.duration, rate, cfg.seed, floating=floating, screen=cfg.screen)
val = motions.split("validation")
real = RealRobot(floating, mismatch, rate)


def plant():
    return RealPlant(real, len(val), task.decimation, seed=cfg.seed + 100, imu_noise=(task.gyro_noise,
                                                                                      task.gravity_noise))


for ckpt in map(Path, sys.argv[1:]):
    rec = json.loads((ckpt.parent / "config.json").read_text())
    ppo = SkillPPOConfig(**{f.name: (tuple(rec["ppo"][f.name]) if f.name == "hidden_dims" else rec["ppo"][f.name])
                            for f in fields(SkillPPOConfig)})
    env = TrackingEnv(plant(), val, task, seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        runner = make_runner(env, runner_cfg(ppo, env.critic_groups), Path(tmp), True)
        runner.load(str(ckpt), map_location="cpu")
    policy = runner.alg.get_policy().as_jit().cpu().eval()
    m = metrics(deploy(policy, plant(), val, task), robot)
    per = " ".join(f"{mo.name.removeprefix('validation_')}:{'ok' if r['success'] else r['cause']}"
                   for mo, r in zip(val, m["motions"]))
    print(f"VAL {ckpt}: success {m['mean']['success'] * len(val):.0f}/{len(val)} falls {m['mean']['falls']} "
          f"MPJPE {1e3 * m['mean']['mpjpe']:.1f} mrad g-MPJPE {1e3 * m['mean']['g_mpjpe']:.0f} mm | {per}",
          flush=True)
