"""Time the validation replay (the fit's check: 4 trajectories of data/dataset.npz, 1999 steps, SolverReplay, CPU, one
torch thread) of the tree on PYTHONPATH: PD and with the residual network at its start, the host-read loop (the CPU's
default) and the branch-free one (the loop a CUDA graph captures); best and median of REPEATS after one warm-up, and a
hash of each output (q, q̇, diverged_at) for comparing two trees' results.

    PYTHONPATH=TREE OMP_NUM_THREADS=1 python replay_ab.py data/dataset.npz [REPEATS]   (this folder's script)
"""
import hashlib
import json
import statistics
import sys
import time

import torch

from wresdyn.data.loading import load_data
from wresdyn.fit.gradfit import build_policy
from wresdyn.learn.residual import obs_stats
from wresdyn.learn.residual_config import ResidualConfig
from wresdyn.sim.rollout import replay_setup, rollout

torch.set_num_threads(1)
torch.manual_seed(0)
ds, robot = load_data(sys.argv[1], None, None)
repeats = int(sys.argv[2]) if len(sys.argv) > 2 else 5
val = ds.split("validation")
policy = build_policy(robot, ResidualConfig(fraction=0.25), *obs_stats(ds.split("train"))).eval()
out = {}
for name, pol in (("pd", None), ("residual", policy)):
    setup = replay_setup(robot, val, ds.rate_hz, pol is not None)
    for loop, free in (("host_read", False), ("branch_free", True)):
        def run():
            with torch.no_grad():
                return rollout(setup.sim, setup.window, pol, policy_worlds=setup.policy_worlds, branch_free=free)
        r = run()
        h = hashlib.sha256(b"".join(t.contiguous().numpy().tobytes() for t in (r.q, r.qd, r.diverged_at))).hexdigest()
        times = []
        for _ in range(repeats):
            t = time.perf_counter()
            run()
            times.append(time.perf_counter() - t)
        out[f"{name}/{loop}"] = {"best_s": min(times), "median_s": statistics.median(times), "sha256": h[:16]}
print(json.dumps(out))
