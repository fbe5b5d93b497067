"""Three differentiable rollouts of the default residual network on the shipped data, their losses and the network's
gradients saved to a file: run on a GPU and on the CPU, the two files are compared (``launch.sh``).

    python gradcheck.py OUT.pt DEVICE
"""

import sys

import numpy as np
import torch
import warp as wp

from wresdyn.data.dataset import load_dataset
from wresdyn.learn.gradfit import GradFitConfig, build_policy
from wresdyn.learn.residual import obs_stats
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim import Simulator, TrajectoryBank
from wresdyn.sim.rollout import rollout

out_path, dev = sys.argv[1], sys.argv[2]
wp.config.quiet = True
torch.set_num_threads(1)
torch.manual_seed(0)
robot = load_robot(DEFAULT_ROBOT)
ds = load_dataset("data/dataset.npz", robot=robot)
B, H = 8, 16
cfg = GradFitConfig(windows=B, horizon=H, horizon_curriculum=(), device=dev)
train = ds.split("train")
policy = build_policy(robot, cfg.residual, *obs_stats(train)).to(dev)
sim = Simulator(robot, B, 1 / ds.rate_hz, device=dev, requires_grad=True)
bank = TrajectoryBank(train, sim.device)
rng = np.random.default_rng(0)
out = []
for _ in range(3):
    traj, start = bank.draw(rng, B, H)
    w = bank.window(traj, start, H)
    run = rollout(sim, w, policy, grad=True)
    loss = (run.q[:, 1:] - w.q[:, 1:]).square().sum() + (run.qd[:, 1:] - w.qd[:, 1:]).square().sum()
    policy.zero_grad()
    loss.backward()
    out.append(torch.cat([p.grad.flatten() for p in policy.parameters()]).clone())
    out.append(loss.detach().reshape(1))
torch.save(torch.cat(out).cpu(), out_path)
