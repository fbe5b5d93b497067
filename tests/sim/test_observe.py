"""The rollout's observation node (wresdyn.sim.observe) against the torch operators it replaces: the same observation
and the same gradients of q, q̇ and the previous q̇ bit for bit, alone, in a chain of steps with truncation (where
autograd's order of adding a velocity's gradients decides the last bits) and in a small gradient fit."""

import dataclasses

import pytest
import torch

from wresdyn.sim.observe import ENV, mode, observe
from wresdyn.sim.residual_kinds import observation

DT = 0.002
CUDA = pytest.param("cuda:0", marks=pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a GPU"))
"""On CUDA torch divides by a Python float as a product with its float32 reciprocal: the node's kernel does the
same, unchecked where no GPU is."""


def _inputs(seed: int, n_worlds: int = 7, n: int = 5, device: str = "cpu"):
    g = torch.Generator().manual_seed(seed)
    q, qd = (torch.randn(n_worlds, n, generator=g).to(device).requires_grad_() for _ in range(2))
    # the previous q̇ near this one, as in a rollout: a difference that cancels most digits
    prev = (qd.detach() * (1.0 + 1e-3 * torch.rand(n_worlds, n, generator=g).to(device))).requires_grad_()
    cmd = torch.randn(n_worlds, 3, n, generator=g).to(device)[:, 1]  # strided, as a window's command of one step
    noise = torch.randn(n_worlds, 4 * n, generator=g).to(device)
    return q, qd, prev, cmd, noise


@pytest.mark.parametrize("device", ["cpu", CUDA])
@pytest.mark.parametrize("kernel", [True, False])
@pytest.mark.parametrize("noisy", [False, True])
@pytest.mark.parametrize("diff", [True, False])
def test_one_node_is_the_torch_operators_bit_for_bit(noisy, diff, kernel, device):
    for seed in range(3):
        q, qd, prev, cmd, noise = _inputs(seed, device=device)
        noise = noise if noisy else None
        qdd = (qd - prev) / DT if diff else prev
        plain = observation(q, qd, qdd, cmd)
        plain = plain if noise is None else plain + noise
        node = observe(q, qd, prev, cmd, noise, DT, diff=diff, kernel=kernel)
        assert torch.equal(node, plain)
        adj = torch.randn(plain.shape, generator=torch.Generator().manual_seed(10 + seed)).to(device)
        for a, b in zip(torch.autograd.grad(plain, (q, qd, prev), adj), torch.autograd.grad(node, (q, qd, prev), adj)):
            assert torch.equal(a, b)


@pytest.mark.parametrize("kernel", [True, False])
def test_only_what_needs_a_gradient_gets_one(kernel):
    q, qd, prev, cmd, noise = _inputs(0)
    obs = observe(q.detach(), qd, prev.detach(), cmd, noise, DT, kernel=kernel)
    (g,) = torch.autograd.grad(obs.square().sum(), (qd,))
    n = q.shape[1]
    assert torch.equal(g, 2 * obs[:, n:2 * n] + 2 * obs[:, 2 * n:3 * n] / DT)  # its slice, then the difference's
    assert not observe(q.detach(), qd.detach(), prev.detach(), cmd, None, DT, kernel=kernel).requires_grad


def _chain(node: bool, kernel: bool = True, device: str = "cpu", steps: int = 12, truncation: int = 5,
           n_worlds: int = 6, n: int = 4):
    """A rollout's autograd graph in small: a policy on each step's observation drives a nonlinear step of (q, q̇);
    every q̇ feeds its step, its observation, the next q̈ and the stacked output. Returns the loss's gradients of the
    policy's weights and of the start state."""
    torch.manual_seed(0)
    policy = torch.nn.Sequential(torch.nn.Linear(4 * n, 16), torch.nn.ELU(), torch.nn.Linear(16, n)).to(device)
    g = torch.Generator().manual_seed(1)
    q0, qd0, qdd0 = (torch.randn(n_worlds, n, generator=g).to(device) for _ in range(3))
    q0.requires_grad_()
    qd0.requires_grad_()
    cmd = torch.randn(n_worlds, steps, n, generator=g).to(device)
    noise = 0.1 * torch.randn(steps, n_worlds, 4 * n, generator=g).to(device)
    q, qd, qdd = q0, qd0, qdd0
    qs, qds = [q], [qd]
    for k in range(steps):
        if node:
            obs = observe(q, qd, qdd, cmd[:, k], noise[k], DT, diff=k > 0, kernel=kernel)
        else:
            obs = observation(q, qd, qdd, cmd[:, k]) + noise[k]
        r = policy(obs)
        qd_new = qd + DT * (r - 3.0 * torch.sin(q) - 0.5 * qd)
        q_new = q + DT * qd_new
        qdd = qd if node else (qd_new - qd) / DT
        q, qd = q_new, qd_new
        qs.append(q)
        qds.append(qd)
        if (k + 1) % truncation == 0:
            q, qd, qdd = q.detach(), qd.detach(), qdd.detach()
    loss = (torch.stack(qs, 1) - cmd.mean()).square().mean() + 0.01 * torch.stack(qds, 1).square().mean()
    return torch.autograd.grad(loss, [*policy.parameters(), q0, qd0])


@pytest.mark.parametrize("device", ["cpu", CUDA])
@pytest.mark.parametrize("kernel", [True, False])
def test_a_truncated_chain_has_the_same_gradients_bit_for_bit(kernel, device):
    for a, b in zip(_chain(False, device=device), _chain(True, kernel, device)):
        assert torch.equal(a, b)
        assert a.abs().max() > 0


def test_the_switch(monkeypatch):
    expected = {None: (None, None), "1": ("torch", "warp"), "warp": ("warp", "warp"), "0": (None, None)}
    for given, (cpu, cuda) in expected.items():
        if given is None:
            monkeypatch.delenv(ENV, raising=False)
        else:
            monkeypatch.setenv(ENV, given)
        assert (mode("cpu"), mode("cuda:0")) == (cpu, cuda)


def test_a_small_gradient_fit_is_the_same_with_the_node(monkeypatch, quadruped, record):
    """A few iterations past the truncation (a detached state in the chain), with observation noise: the same losses
    and weights to the last bit with the node as with the torch operators."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.fit.gradfit import GradFitConfig, fit
    from wresdyn.learn.residual import ResidualConfig

    data = record(quadruped, Mismatch(friction=0.02, damping=0.4), {"train": 2, "validation": 1}, seconds=0.3,
                  amplitude=0.4)
    cfg = GradFitConfig(residual=ResidualConfig(hidden_dims=(16,)), horizon=6, horizon_curriculum=(), windows=4,
                        iterations=4, obs_noise=0.1, grad_truncation=4, solver="featherstone")
    runs = {}
    for given in ("0", "1", "warp"):  # no node, the node's torch operators, its Warp kernels
        monkeypatch.setenv(ENV, given)
        runs[given] = fit(quadruped, data, dataclasses.replace(cfg), log=lambda *_: None)
    plain, plain_curve = runs.pop("0")
    for node, node_curve in runs.values():
        assert [r["loss"] for r in node_curve] == [r["loss"] for r in plain_curve]
        for a, b in zip(plain.state_dict().values(), node.state_dict().values()):
            assert torch.equal(a, b)


@pytest.mark.parametrize("device", ["cpu", CUDA])
def test_a_rollout_drawing_its_noise_is_the_same_with_the_node(monkeypatch, quadruped, record, device):
    """The rollout's other noise source, a generator drawn at each step: the same states, actions and gradients (on
    CUDA eagerly, outside the fit's captured graph; ``1`` is the Warp kernels there)."""
    import numpy as np

    from wresdyn.data.mismatch import Mismatch
    from wresdyn.fit.gradfit import build_policy
    from wresdyn.learn.residual import ResidualConfig, obs_stats
    from wresdyn.sim import Simulator, TrajectoryBank, rollout

    train = record(quadruped, Mismatch(damping=0.4), {"train": 1}, seconds=0.2, amplitude=0.4).split("train")
    policy = build_policy(quadruped, ResidualConfig(hidden_dims=(16,)), *obs_stats(train)).to(device)
    sim = Simulator(quadruped, 3, DT, solver="featherstone", requires_grad=True, device=device)
    window = TrajectoryBank(train, sim.device).sample(np.random.default_rng(2), 3, 7)
    results = {}
    for given in ("0", "1", "warp"):
        monkeypatch.setenv(ENV, given)
        out = rollout(sim, window, policy, grad=True, truncation=3, obs_noise=0.5,
                      generator=torch.Generator(device=device).manual_seed(3))
        grads = torch.autograd.grad((out.q[:, 1:] - window.q[:, 1:]).square().sum() + out.actions.square().sum(),
                                    list(policy.parameters()))
        results[given] = [out.q, out.qd, out.actions, *grads]
    for given in ("1", "warp"):
        for a, b in zip(results["0"], results[given]):
            assert torch.equal(a, b)
    assert results["0"][3].abs().max() > 0
