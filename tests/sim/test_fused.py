"""Fused window rollouts (:func:`wresdyn.sim.fused.fused_rollout`) against the step-by-step driver
(:func:`wresdyn.sim.rollout.rollout`) on the humanoid: the same kernels, so the same states and the same gradients
to every physical parameter."""

import numpy as np
import pytest
import torch

from wresdyn.sim import Simulator, TrajectoryBank, rollout
from wresdyn.sim.fused import fused_rollout
from wresdyn.sim.physics import PhysicalParams, PhysicsModel

FIT = ("kp", "kd", "armature", "damping", "friction", "effort", "bodies")


def _run(sim, model, window, fused):
    model.zero_grad()
    sim.set_physics(model())
    q, qd = fused_rollout(sim, window) if fused else (lambda r: (r.q, r.qd))(rollout(sim, window, grad=True))
    loss = ((q[:, 1:] - window.q[:, 1:]) ** 2).mean() + 0.01 * ((qd[:, 1:] - window.qd[:, 1:]) ** 2).mean()
    loss.backward()
    return q.detach(), {n: p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}


def test_fused_rollout_matches_the_step_by_step_replay(humanoid, data):
    rate = data.rate_hz
    start = PhysicalParams.nominal(humanoid)
    model = PhysicsModel(humanoid, start, fit=FIT, dt=1.0 / rate)
    bank = TrajectoryBank(data.split("train"), "cpu", 2.0)
    window = bank.sample(np.random.default_rng(0), 3, 24)
    sim = Simulator(humanoid, 3, 1.0 / rate, requires_grad=True, param_grads=True)
    q_step, g_step = _run(sim, model, window, fused=False)
    q_fused, g_fused = _run(sim, model, window, fused=True)
    # the same kernel arithmetic in the same order: bitwise equal states
    assert torch.equal(q_step, q_fused)
    assert set(g_step) == set(g_fused) and len(g_step) == 8
    for name, g in g_step.items():
        # the adjoints sum over worlds in another order: float32 rounding, measured 1e-7 relative
        assert float((g - g_fused[name]).norm()) <= 1e-5 * float(g.norm()) + 1e-12, name
    with torch.no_grad():
        q_nograd, _ = fused_rollout(sim, window)
    assert torch.equal(q_nograd, q_step)


def test_fused_rollout_passes_the_targets_gradient_to_an_identified_delay(humanoid, data):
    dt = 1.0 / data.rate_hz
    start = PhysicalParams.nominal(humanoid)
    start.delay = np.full(humanoid.n_dof, 2.5 * dt)
    model = PhysicsModel(humanoid, start, fit=("kp", "damping", "delay"), dt=dt)
    bank = TrajectoryBank(data.split("train"), "cpu", 0.0)
    traj, first = bank.draw(np.random.default_rng(1), 3, 24)
    sim = Simulator(humanoid, 3, dt, requires_grad=True, param_grads=True)
    grads, states = {}, {}
    for fused in (False, True):
        model.zero_grad()
        bank.set_delay(model.delay_steps().float())  # the targets now depend on the delay
        window = bank.window(traj, first, 24)
        assert window.target.requires_grad
        sim.set_physics(model())
        q, qd = fused_rollout(sim, window) if fused else (lambda r: (r.q, r.qd))(rollout(sim, window, grad=True))
        ((q[:, 1:] - window.q[:, 1:]) ** 2).mean().backward()
        states[fused] = q.detach()
        grads[fused] = {n: p.grad.clone() for n, p in model.named_parameters() if p.grad is not None}
    assert torch.equal(states[False], states[True])
    assert {"u_kp", "u_damping", "u_delay"} <= set(grads[False]) and set(grads[False]) == set(grads[True])
    assert float(grads[True]["u_delay"].abs().max()) > 0.0
    for name, g in grads[False].items():
        assert float((g - grads[True][name]).norm()) <= 1e-5 * float(g.norm()) + 1e-12, name


def test_fused_rollout_refuses_what_it_cannot_replay(humanoid):
    sim = Simulator(humanoid, 2, 0.002, substeps=2)
    bank = TrajectoryBank([_still(humanoid)], "cpu", 0.0)
    with pytest.raises(ValueError, match="one substep"):
        fused_rollout(sim, bank.whole().repeat(2))
    with pytest.raises(ValueError, match="worlds"):
        fused_rollout(Simulator(humanoid, 3, 0.002), bank.whole().repeat(2))


def _still(robot):
    from types import SimpleNamespace

    q = np.tile(robot.q0, (10, 1))
    return SimpleNamespace(q=q, qd=np.zeros_like(q), qdd=np.zeros_like(q), q_cmd=q)
