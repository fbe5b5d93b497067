"""Probe (not adopted): the real robot's floor deployments of the shipped (a), (b), (d) and the reference, one split
after the other (4 validation, 5 held-out motions at 500 Hz), serially and in threads side by side, each plant with a
``mujoco.rollout.Rollout`` pool of its own (the module's persistent pool is one for the process). The policies are
loaded first: ``torch.export``'s loader is not thread-safe. Prints both wall-clocks, the process's CPU time of each
(threads get a larger share of a host other jobs load: the CPU time tells that apart) and whether every deployment's
metrics are the same: ``python threads_probe.py MISMATCH THREADS``."""

import hashlib
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor

from mujoco import rollout

from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import RealRobot
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.skills.evaluate import deploy, metrics
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import RealPlant
from wresdyn.skills.shipped import shipped_folder
from wresdyn.skills.skill_config import FloorTaskConfig
from wresdyn.skills.skill_ppo import load_skill

stand = load_robot(DEFAULT_ROBOT)
floating = load_robot(stand.source, base="floating")
motions = make_motions(stand, {"validation": 1, "heldout": 1}, 4.0, 500.0, 0, floating=floating, workers=1)
task = FloorTaskConfig()
real = RealRobot(floating, Mismatch.load(sys.argv[1]), 500.0)
policies = {n: None if n is None else load_skill(shipped_folder(n))
            for n in ("floor_nominal", "floor_calibrated", "floor_oracle", None)}
jobs = [(s, n) for s in ("validation", "heldout") for n in policies]


class OwnPool:
    """A plant's ``_rollout`` stand-in: its own ``Rollout`` thread pool instead of the module's persistent one."""

    def __init__(self, threads: int):
        self.pool = rollout.Rollout(nthread=threads)

    def rollout(self, model, data, state, control, persistent_pool=True):
        return self.pool.rollout(model, data, state, control)


def one(job, own: bool = False) -> str:
    split, name = job
    mot = motions[split]
    plant = RealPlant(real, len(mot), task.decimation, seed=100, imu_noise=(task.gyro_noise, task.gravity_noise))
    if own:
        plant._rollout = OwnPool(len(plant._datas))
    dep = deploy(policies[name], plant, mot, task)
    return hashlib.sha256(json.dumps(metrics(dep), sort_keys=True, default=str).encode()).hexdigest()[:16]


one(jobs[0])  # warm: kernels and first calls out of the timings
t, c = time.perf_counter(), time.process_time()
serial = [one(j) for j in jobs]
serial_s, serial_cpu = time.perf_counter() - t, time.process_time() - c
t, c = time.perf_counter(), time.process_time()
with ThreadPoolExecutor(int(sys.argv[2])) as pool:
    threaded = list(pool.map(lambda j: one(j, True), jobs))
print(json.dumps({"deployments": len(jobs), "serial_s": round(serial_s, 2), "serial_cpu_s": round(serial_cpu, 2),
                  "threads": int(sys.argv[2]), "threads_s": round(time.perf_counter() - t, 2),
                  "threads_cpu_s": round(time.process_time() - c, 2), "same_metrics": serial == threaded}))
