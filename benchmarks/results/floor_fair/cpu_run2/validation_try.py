"""One fine-tuning configuration of the floor CPU run, judged on VALIDATION motions only: the steps of
``wresdyn deploy --floor`` up to the policies (same motions, same shipped (a), a finished calibrated fit reused),
then every policy and the open-loop reference deployed on the real robot's floor over the validation motions, and
nothing on held-out motions (none are drawn). Prints one line per policy and writes ``OUT/validation.json``.

    PYTHONPATH=$PWD OMP_NUM_THREADS=1 python benchmarks/results/floor_fair/cpu_run2/validation_try.py OUT \
        --calibrated RUN --finetune 120 [--num-worlds 64] [--finetune-std 0.3] [--lr 1e-3] [--beside]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

from wresdyn.data.loading import load_data
from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.experiments.deploy_config import FloorDeployConfig
from wresdyn.experiments.nominal_policy import nominal_source
from wresdyn.experiments.skills import _plants, _train_all
from wresdyn.experiments.zero_shot import start_benchmark
from wresdyn.robot import load_robot
from wresdyn.skills.evaluate import deploy, metrics
from wresdyn.skills.motions import make_motions
from wresdyn.skills.skill_config import FloorTaskConfig, SkillPPOConfig
from wresdyn.skills.skill_ppo import load_skill

ROOT = Path(__file__).resolve().parents[4]

p = argparse.ArgumentParser()
p.add_argument("out")
p.add_argument("--calibrated", required=True)
p.add_argument("--finetune", type=int, default=30)
p.add_argument("--num-worlds", type=int, default=64)
p.add_argument("--oracle-num-worlds", type=int, default=None)
p.add_argument("--finetune-std", type=float, default=None)
p.add_argument("--lr", type=float, default=1e-3)
p.add_argument("--steps", type=int, default=24)
p.add_argument("--epochs", type=int, default=5)
p.add_argument("--minibatches", type=int, default=4)
p.add_argument("--desired-kl", type=float, default=0.01)
p.add_argument("--beside", action="store_true", help="the oracle in a process of its own beside (b)")
p.add_argument("--policies", nargs="+", default=["a_nominal", "b_calibrated", "d_oracle"])
a = p.parse_args()

t_start = time.perf_counter()
out = Path(a.out)
ds, robot = load_data(str(ROOT / "data" / "dataset.npz"))
mismatch = Mismatch.load(str(ROOT / "data" / "mismatch_default.toml"))
cfg = FloorDeployConfig(finetune=a.finetune, num_worlds=a.num_worlds, oracle_num_worlds=a.oracle_num_worlds,
                        finetune_std=a.finetune_std, oracle_beside=a.beside)
task = FloorTaskConfig()
ppo = SkillPPOConfig(learning_rate=a.lr, num_steps_per_env=a.steps, num_learning_epochs=a.epochs,
                     num_mini_batches=a.minibatches, desired_kl=a.desired_kl)
policies, ppo, mismatch, counts = start_benchmark(out, cfg, ppo, mismatch, ds, a.policies)
plant_robot = load_robot(robot.source, gains=robot.gains, base="floating")
rate = float(ds.rate_hz)
meta = {"motions": {"seed": cfg.seed, "counts": counts, "duration": cfg.duration, "floor": True,
                    "screened": cfg.screen}}
cfg = replace(cfg, nominal=nominal_source(cfg))
motions = make_motions(robot, {k: n for k, n in counts.items() if k != "heldout"}, cfg.duration, rate, cfg.seed,
                       floating=plant_robot, screen=cfg.screen)
assert "heldout" not in motions.splits or not motions.split("heldout")
real = RealRobot(plant_robot, mismatch, rate)
runs = {"calibrated": Path(a.calibrated), "delta_action": None}
t0 = time.perf_counter()
wall = _train_all(policies, plant_robot, real, motions.split("train"), task, ppo, cfg, runs, meta, out, mismatch,
                  print)
train_s = time.perf_counter() - t0
real_plant, _ = _plants(task, real, plant_robot, rate, runs, cfg.device)
val = motions.split("validation")
res = {"args": vars(a), "train_wall_s": wall, "train_total_s": train_s, "validation": {}}
for name in ("reference", *policies):
    policy = None if name == "reference" else load_skill(out / "skills" / name)
    m = metrics(deploy(policy, real_plant(len(val), cfg.seed + 100), val, task), robot)
    res["validation"][name] = m
    per = " ".join(f"{mo.name.removeprefix('validation_')}:{'ok' if r['success'] else r['cause']}"
                   for mo, r in zip(val, m["motions"]))
    print(f"VAL {name}: success {m['mean']['success'] * len(val):.0f}/{len(val)} falls {m['mean']['falls']} "
          f"MPJPE {1e3 * m['mean']['mpjpe']:.1f} mrad g-MPJPE {1e3 * m['mean']['g_mpjpe']:.0f} mm | {per}")
res["wall_s"] = time.perf_counter() - t_start
(out / "validation.json").write_text(json.dumps(res, indent=1, default=str))
print(f"train {train_s:.0f} s ({', '.join(f'{k} {v:.0f} s' for k, v in wall.items())}); total {res['wall_s']:.0f} s")
