"""Count torch operators per step of the masked (branch-free) validation replay, PD and with the residual network
(at its start), on the CPU: the operators a captured CUDA graph holds as kernels beside the solver's step. The Warp
launch count it prints is not the solver's (the solver launches through its own reference to ``wp.launch``).

    PYTHONPATH=. OMP_NUM_THREADS=1 python benchmarks/results/speed/fitcut57_cpu/count_ops.py data/dataset.npz
"""
import collections
import sys

import torch
import warp as wp
from torch.utils._python_dispatch import TorchDispatchMode

from wresdyn.data.loading import load_data
from wresdyn.fit.gradfit import build_policy
from wresdyn.learn.residual import obs_stats
from wresdyn.learn.residual_config import ResidualConfig
from wresdyn.sim import Simulator
from wresdyn.sim.rollout import replay_setup, rollout

torch.set_num_threads(1)
ds, robot = load_data(sys.argv[1], None, None)
val = ds.split("validation")


class Count(TorchDispatchMode):
    def __init__(self):
        super().__init__()
        self.ops = collections.Counter()

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.ops[str(func.overloadpacket.__name__)] += 1
        return func(*args, **(kwargs or {}))


launches = collections.Counter()
orig = wp.launch


def counted(kernel, *a, **k):
    launches[getattr(kernel, "key", str(kernel))] += 1
    return orig(kernel, *a, **k)


wp.launch = counted
import wresdyn.sim.simulator as simmod  # noqa: E402
if hasattr(simmod, "wp"):
    simmod.wp.launch = counted
policy = build_policy(robot, ResidualConfig(fraction=0.25), *obs_stats(ds.split("train"))).eval()
for name, pol in (("PD", None), ("residual", policy)):
    setup = replay_setup(robot, val, ds.rate_hz, pol is not None)
    win = setup.window
    steps = win.steps
    launches.clear()
    with torch.no_grad(), Count() as c:
        rollout(setup.sim, win, pol, policy_worlds=setup.policy_worlds, branch_free=True)
    total = sum(c.ops.values())
    print(f"{name}: {steps} steps, torch ops {total} ({total / steps:.1f} a step), warp launches "
          f"{sum(launches.values())} ({sum(launches.values()) / steps:.1f} a step)")
    print("  per step:", ", ".join(f"{k} {v / steps:.1f}" for k, v in c.ops.most_common() if v >= steps))
    print("  warp:", dict(launches))
