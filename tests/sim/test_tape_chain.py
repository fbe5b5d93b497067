""":mod:`wresdyn.sim.tape_chain`: the gradient fit's rollout with the tile kernels as one autograd node, the state's
gradient summed in the simulator's rows, against the step loop (two autograd nodes a step, autograd summing each
state's gradients): the same loss and parameter gradients, bit for bit on the CPU (measured: equal), through truncated
windows, observation noise, windows of several lengths one after another (rows left by a longer window, a row array
first reached) and a block of tile rows only partly filled. A gradient summed twice, one dropped at a truncation or a
row not zeroed would show as a difference."""

import dataclasses

import numpy as np
import pytest
import torch

from wresdyn.fit.gradfit import GradFitConfig, GradFitIteration, build_policy, fit
from wresdyn.learn.adam import Adam
from wresdyn.learn.residual import ResidualConfig, obs_stats
from wresdyn.learn.window_fit import start_window_fit
from wresdyn.sim import Simulator, TrajectoryBank
from wresdyn.sim.bank import servo_goal_accel
from wresdyn.sim.tape_chain import CHAIN_ENV

B = 5  # windows: one tile block of 8 rows, partly filled
CFG = GradFitConfig(residual=ResidualConfig(fraction=0.25, hidden_dims=(32, 32)), windows=B, fused_network=True,
                    network_tiles=True, grad_truncation=4, obs_noise=0.1)


def _gradients(robot, data, monkeypatch, chain: bool, truncation: int, lengths=(10, 3, 15), device="cpu"):
    """Loss and parameter gradients of one window batch at each of ``lengths``, one simulator and network for all."""
    monkeypatch.setenv(CHAIN_ENV, "1" if chain else "0")
    cfg = dataclasses.replace(CFG, grad_truncation=truncation, device=device)
    _, train, dt = start_window_fit(cfg, data)
    torch.manual_seed(0)
    policy = build_policy(robot, cfg.residual, *obs_stats(train)).to(device)
    with torch.no_grad():  # away from the zero-residual start, so every layer's gradient is non-trivial
        for p in policy.parameters():
            p.add_(0.05 * torch.randn_like(p))
    sim = Simulator(robot, B, dt, solver=cfg.solver, device=device, requires_grad=True)
    bank = TrajectoryBank(train, sim.device, 0.0, servo_goal_accel(robot, None, dt, sim.device))
    optim = Adam(policy.parameters(), lr=cfg.lr, fused=True)
    step = GradFitIteration(cfg, sim, bank, policy, optim, cfg.obs_noise, False)
    rng, out = np.random.default_rng(0), []
    for h in lengths:
        traj, start = bank.draw(rng, B, h)
        noise = torch.randn((h, B, 4 * robot.n_dof), generator=torch.Generator().manual_seed(h)).to(device)
        optim.zero_grad()
        loss, _ = step.gradients(traj, start, h, noise)
        out.append((loss.detach(), [p.grad.clone() for p in policy.parameters()]))
    return out


@pytest.mark.parametrize("device", ["cpu", pytest.param("cuda:0", marks=pytest.mark.skipif(
    not torch.cuda.is_available(), reason="no GPU"))])
@pytest.mark.parametrize("truncation", [4, None])
def test_chained_rollout_gives_the_step_loop_bit_for_bit(robot, data, monkeypatch, truncation, device):
    steps = _gradients(robot, data, monkeypatch, False, truncation, device=device)
    chained = _gradients(robot, data, monkeypatch, True, truncation, device=device)
    for (loss_s, grads_s), (loss_c, grads_c) in zip(steps, chained, strict=True):
        assert torch.equal(loss_c, loss_s)
        assert all(g.abs().max() > 0 for g in grads_s), "a layer without gradient: the test would miss it"
        for a, b in zip(grads_c, grads_s, strict=True):
            assert torch.equal(a, b)


def test_truncation_cuts_the_chained_gradient(robot, data, monkeypatch):
    # the property the bit-for-bit test above rests on, seen from the other side: the cut changes the gradients
    cut = _gradients(robot, data, monkeypatch, True, 4, lengths=(10,))
    whole = _gradients(robot, data, monkeypatch, True, None, lengths=(10,))
    assert not torch.equal(cut[0][1][0], whole[0][1][0])


def test_the_fit_takes_the_chain_only_with_the_tile_kernels(robot, data, monkeypatch):
    import importlib

    rollout = importlib.import_module("wresdyn.sim.rollout")  # the module (the package exports its function)
    runs, chained = [], rollout.chained_rollout
    monkeypatch.setattr(rollout, "chained_rollout", lambda *a: runs.append(a[-1]) or chained(*a))
    tiny = dataclasses.replace(CFG, windows=4, horizon_curriculum=(2, 4), iterations=4, select_every=2)
    fit(robot, data, tiny, log=lambda *_: None)
    assert len(runs) == 4 and set(runs) == {4}  # every iteration, with the config's truncation
    runs.clear()
    fit(robot, data, dataclasses.replace(tiny, network_tiles=False), log=lambda *_: None)
    assert runs == []
