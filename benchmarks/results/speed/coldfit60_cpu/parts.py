"""The per-check costs this change moves or removes, on this host (CPU): a checkpoint of a 1880-row curve (the GPU
fit's identification at its end) written in place against its host copy (what the loop still pays with the writer
thread), and a validation replay's set-up against its rollout (data/dataset.npz's validation split, the fit's
validation simulator).

    PYTHONPATH=. python benchmarks/results/speed/coldfit60_cpu/parts.py
"""
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from wresdyn.data.loading import load_data
from wresdyn.learn.runs import RunFolder, host_copy, save_checkpoint
from wresdyn.sim import Simulator
from wresdyn.sim.physics import PhysicalParams
from wresdyn.sim.rollout import replay_setup, run_replay

torch.set_num_threads(1)


def best_of(f, n=5):
    t = []
    for _ in range(n):
        s = time.perf_counter()
        f()
        t.append(time.perf_counter() - s)
    return min(t), float(np.median(t))


rows = [{"iteration": i + 1, "wall": 0.1 * i, "sim_steps": 1000 * i, "loss": 0.1, "pos": 0.01, "vel": 0.02,
         **({"validation": 0.05} if i % 40 == 39 else {})} for i in range(1880)]
model = {f"p{i}": torch.randn(21) for i in range(12)}
state = {"model": model, "optim": {"state": {i: {"step": torch.tensor(1.0), "exp_avg": torch.randn(21),
                                                  "exp_avg_sq": torch.randn(21)} for i in range(12)},
                                   "param_groups": [{"lr": 0.01, "params": list(range(12))}]}}
with tempfile.TemporaryDirectory() as d:
    for n in (40, 940, 1880):
        data = {**state, "meta": {"config": {"a": 1}, "curve": rows[:n], "iteration": n}, "best": model}
        inline = best_of(lambda: save_checkpoint(data, Path(d) / "c.pt"))
        copy = best_of(lambda: host_copy(data))
        print(f"checkpoint, {n:4d} curve rows: written in place {inline[0] * 1e3:7.1f} ms (median {inline[1] * 1e3:.1f}),"
              f" host copy {copy[0] * 1e3:5.2f} ms (median {copy[1] * 1e3:.2f})")

ds, robot = load_data("data/dataset.npz", None, None)
val = ds.split("validation")
print(f"validation: {len(val)} trajectories, {sum(len(t.q) for t in val)} samples")
physics = PhysicalParams.nominal(robot)
sim = Simulator(robot, len(val), 1.0 / ds.rate_hz)
setup = replay_setup(robot, val, ds.rate_hz, False, sim=sim, physics=physics)
fresh = best_of(lambda: replay_setup(robot, val, ds.rate_hz, False, sim=sim, physics=physics), 3)
reused = best_of(lambda: replay_setup(robot, val, ds.rate_hz, False, sim=sim, physics=physics, reuse=setup), 3)
replay = best_of(lambda: run_replay(setup), 3)
print(f"validation set-up fresh {fresh[0] * 1e3:.1f} ms, reusing the banks {reused[0] * 1e3:.1f} ms, "
      f"kept (fixed physics) 0 ms; the replay itself {replay[0] * 1e3:.0f} ms")
