"""Gradient fit through the differentiable Warp simulation: gradients vs central finite differences, a fit
that reduces the replay error, and checkpoint/resume."""

import dataclasses

import numpy as np
import pytest
import torch
from _tiny_data import make_dataset

from wresdyn.learn.gradfit import GradFitConfig, build_policy, fit, window_loss
from wresdyn.learn.residual import ResidualConfig, obs_stats
from wresdyn.learn.runs import RunError
from wresdyn.robot.description import load_robot
from wresdyn.sim import Simulator, TrajectoryBank, rollout

DT = 0.002
FD_RTOL = 3e-2
"""Relative L2 error allowed between the tape gradient and central differences: the simulation runs in
float32, so a central difference with eps = 1e-2 carries ~1e-7·|L|/eps round-off, ~1 % of these gradients."""


@pytest.fixture(scope="module")
def cartpole():
    return load_robot("newton:cartpole.urdf", gains="examples/gains/cartpole.toml")


def test_gradient_wrt_residual_torque_matches_finite_differences(cartpole):
    b, h = 2, 6
    sim = Simulator(cartpole, b, DT, solver="featherstone", requires_grad=True)
    rng = np.random.default_rng(0)
    f = lambda *s, lo=-0.3, hi=0.3: torch.tensor(rng.uniform(lo, hi, s), dtype=torch.float32)  # noqa: E731
    q0, qd0, cmd, q_ref = f(b, 3), f(b, 3, lo=-1, hi=1), f(b, h, 3), f(b, h, 3)

    def loss(tau):
        q, qd, total = q0, qd0, 0.0
        for k in range(h):
            q, qd = sim.step_diff(k, q, qd, cmd[:, k], tau[:, k])
            total = total + ((q - q_ref[:, k]) ** 2).sum() + 0.01 * (qd**2).sum()
        return total

    tau = f(b, h, 3, lo=-2, hi=2).requires_grad_()
    loss(tau).backward()
    fd = torch.zeros_like(tau)
    eps = 1e-2
    with torch.no_grad():
        for idx in np.ndindex(*tau.shape):
            e = torch.zeros_like(tau)
            e[idx] = eps
            fd[idx] = (loss(tau + e) - loss(tau - e)) / (2 * eps)
    assert fd.abs().max() > 1e-5  # the residual really moves the loss
    assert (tau.grad - fd).norm() / fd.norm() < FD_RTOL


@pytest.mark.parametrize("kind", ["torque", "delta_action"])
def test_gradient_wrt_network_parameters_matches_finite_differences(cartpole, kind):
    torch.manual_seed(0)
    data = make_dataset(cartpole, seconds=0.4, counts=(2, 0, 0))
    # the cartpole URDF's effort limit is 1000: 0.5 % of it is a residual of the size the PD drives exert
    cfg = GradFitConfig(residual=ResidualConfig(kind=kind, hidden_dims=(16,), output_gain=1.0, fraction=0.005),
                        horizon=6, horizon_curriculum=(), windows=2)
    train = data.split("train")
    policy = build_policy(cartpole, cfg.residual, *obs_stats(train))
    sim = Simulator(cartpole, cfg.windows, DT, solver="featherstone", requires_grad=True)
    w = TrajectoryBank(train, sim.device).sample(np.random.default_rng(1), cfg.windows, cfg.horizon)

    def loss():
        out = rollout(sim, w, policy, grad=True)
        return window_loss(cfg, out.q[:, 1:], out.qd[:, 1:], out.actions, w.q[:, 1:], w.qd[:, 1:],
                           policy.scale if kind == "torque" else None)[0]

    params = list(policy.parameters())
    policy.zero_grad()
    loss().backward()
    g = torch.cat([p.grad.flatten() for p in params])
    direction = torch.randn(g.shape, generator=torch.Generator().manual_seed(0))
    direction /= direction.norm()
    eps = 1e-3  # small enough not to cross the action clamp's kinks

    def shifted(sign):
        with torch.no_grad():
            offset = 0
            for p in params:
                p += sign * eps * direction[offset : offset + p.numel()].view_as(p)
                offset += p.numel()
            value = float(loss())
            offset = 0
            for p in params:
                p -= sign * eps * direction[offset : offset + p.numel()].view_as(p)
                offset += p.numel()
        return value

    fd = (shifted(1.0) - shifted(-1.0)) / (2 * eps)
    analytic = float(g @ direction)
    assert abs(fd) > 1e-6
    assert abs(analytic - fd) <= FD_RTOL * abs(fd) + 1e-6


def test_fit_reduces_replay_error_and_resumes(tmp_path, quadruped):
    data = make_dataset(quadruped, seconds=0.3, counts=(3, 0, 0), amplitude=0.4)
    cfg = GradFitConfig(residual=ResidualConfig(hidden_dims=(64, 64)), horizon=8, horizon_curriculum=(), windows=8, iterations=40, lr=3e-3,
                        solver="featherstone")
    train = data.split("train")
    eval_sim = Simulator(quadruped, 8, DT, solver="featherstone")
    w = TrajectoryBank(train, eval_sim.device).sample(np.random.default_rng(123), 8, 8)

    def error(policy):
        with torch.no_grad():
            return float((rollout(eval_sim, w, policy).q[:, 1:] - w.q[:, 1:]).abs().mean())

    untrained = build_policy(quadruped, cfg.residual, *obs_stats(train))
    policy, curve = fit(quadruped, data, cfg, out=tmp_path, log=lambda *_: None)
    assert error(policy) < 0.7 * error(untrained)
    assert len(curve) == 40 and curve[-1]["sim_steps"] == 40 * 8 * 8 * 2
    # the iteration count shapes the learning-rate and horizon schedule: a resume that changes it is refused
    with pytest.raises(RunError, match="iterations = 40, now 44"):
        fit(quadruped, data, dataclasses.replace(cfg, iterations=44), out=tmp_path, log=lambda *_: None)
    with pytest.raises(RunError, match="residual.fraction"):
        fit(quadruped, data, dataclasses.replace(cfg, residual=dataclasses.replace(cfg.residual, fraction=0.3)),
            out=tmp_path, log=lambda *_: None)


def test_interrupted_fit_resumes_to_the_same_policy(tmp_path, quadruped):
    """Stopping at ``until`` and resuming gives the uninterrupted run's parameters exactly: the checkpoint carries
    the optimiser, the window sampler and the observation-noise generator."""
    data = make_dataset(quadruped, seconds=0.3, counts=(2, 0, 0), amplitude=0.4)
    cfg = GradFitConfig(residual=ResidualConfig(hidden_dims=(16,)), horizon=4, horizon_curriculum=(), windows=4,
                        iterations=6, obs_noise=0.1, solver="featherstone")
    straight, _ = fit(quadruped, data, cfg, log=lambda *_: None)
    fit(quadruped, data, cfg, out=tmp_path, log=lambda *_: None, until=3)
    resumed, _ = fit(quadruped, data, cfg, out=tmp_path, log=lambda *_: None)
    for a, b in zip(straight.state_dict().values(), resumed.state_dict().values()):
        assert torch.equal(a, b)
    noiseless, _ = fit(quadruped, data, dataclasses.replace(cfg, obs_noise=0.0), log=lambda *_: None)
    assert not torch.equal(next(iter(noiseless.parameters())), next(iter(straight.parameters())))


def test_parametric_baseline_fits_friction_and_gains(quadruped):
    """The "real" quadruped has extra dry friction and damping and 0.9x kp / 1.2x kd (tests/_tiny_data.py)."""
    torch.manual_seed(0)
    data = make_dataset(quadruped, seconds=0.6, counts=(3, 0, 0), amplitude=0.4)
    cfg = GradFitConfig(model="parametric", horizon=16, horizon_curriculum=(), windows=8, iterations=40, lr=3e-2,
                        solver="featherstone")
    train = data.split("train")
    sim = Simulator(quadruped, 8, DT, solver="featherstone")
    w = TrajectoryBank(train, sim.device).sample(np.random.default_rng(5), 8, 16)

    def error(policy):
        with torch.no_grad():
            return float((rollout(sim, w, policy).q[:, 1:] - w.q[:, 1:]).abs().mean())

    start = build_policy(quadruped, cfg.residual, *obs_stats(train), model="parametric")
    policy, _ = fit(quadruped, data, cfg, log=lambda *_: None)
    assert error(policy) < 0.5 * error(start)
    found, initial = policy.parameters_physical(), start.parameters_physical()
    assert found["friction"].mean() > 1.5 * initial["friction"].mean()  # it finds dry friction (truth: 8x the start)
    assert found["kd_scale"].mean() > 1.0  # and the stiffer damping of the real drives
