"""The simulation layer's autograd bridge: :meth:`Simulator.step_diff` gradients against central finite differences,
for SolverReplay (the default solver of a fixed base) and SolverFeatherstone.

The loss runs a few differentiable steps from (q0, q̇0) with a PD target and a residual torque per step, so the
gradient of each input flows through the Warp tape of every step after it and through the bridge between steps.
"""

import numpy as np
import pytest
import torch

from wresdyn.sim import Simulator

DT = 0.002
FD_RTOL = 1e-2
"""Relative L2 error allowed between the tape gradient and central differences. The simulation runs in float32:
the loss (a sum of O(1) squares over a few steps) carries ~1e-7·|L| round-off, so a central difference with step
eps carries ~1e-7·|L|/eps; at the steps of :data:`EPS` that is at most 0.2 % of these gradients (measured: the
error shrinks 10x for a 10x larger eps, so it is round-off, and the O(eps²) truncation error is below it)."""
EPS = {"q0": 1e-3, "qd0": 1e-2, "target": 1e-3, "tau": 1e-2}
"""Finite-difference step per input [rad, rad/s, rad, N*m]: positions move the loss through the PD stiffness
(kp ~ 20-200 N*m/rad), velocities and torques through a step's dt, so the position steps are 10x smaller for a
change of the loss of the same size, well above the round-off and small enough not to leave the linear range."""


def _inputs(robot, b, h, seed=0):
    """Start state, PD targets and residual torques inside the joint limits, about mid-range."""
    rng = np.random.default_rng(seed)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -0.5)
    hi = np.where(np.isfinite(robot.upper), robot.upper, 0.5)
    mid, half = (lo + hi) / 2, np.minimum((hi - lo) / 2, 0.5)
    f = lambda x: torch.tensor(x, dtype=torch.float32)  # noqa: E731
    q0 = f(mid + 0.3 * half * rng.uniform(-1, 1, (b, robot.n_dof)))
    qd0 = f(rng.uniform(-1, 1, (b, robot.n_dof)))
    target = f(mid + 0.3 * half * rng.uniform(-1, 1, (b, h, robot.n_dof)))
    # residual torques of a few % of the effort limit: far from the drive's torque clamp
    tau = f(0.03 * np.minimum(robot.effort, 100.0) * rng.uniform(-1, 1, (b, h, robot.n_dof)))
    q_ref = f(mid + 0.3 * half * rng.uniform(-1, 1, (b, h, robot.n_dof)))
    return {"q0": q0, "qd0": qd0, "target": target, "tau": tau}, q_ref


def _loss_fn(sim, q_ref):
    def loss(q0, qd0, target, tau):
        q, qd, total = q0, qd0, 0.0
        for k in range(target.shape[1]):
            q, qd = sim.step_diff(k, q, qd, target[:, k], tau[:, k])
            total = total + ((q - q_ref[:, k]) ** 2).sum() + 0.01 * (qd**2).sum()
        return total

    return loss


def _tape_gradients(loss, x):
    x = {k: v.clone().requires_grad_() for k, v in x.items()}
    loss(**x).backward()
    return {k: v.grad for k, v in x.items()}


def _shifted(loss, x, name, delta):
    """Central difference of ``loss`` along ``delta`` added to input ``name``."""
    with torch.no_grad():
        plus = float(loss(**{**x, name: x[name] + delta}))
        minus = float(loss(**{**x, name: x[name] - delta}))
    return plus - minus


@pytest.mark.parametrize("solver", ["replay", "featherstone"])
def test_step_diff_gradients_match_finite_differences(cartpole, solver):
    """Every element of the gradient w.r.t. the start state, the PD targets and the residual torques of 6 steps."""
    b, h = 2, 6
    sim = Simulator(cartpole, b, DT, solver=solver, requires_grad=True)
    assert sim.solver_kind == solver
    x, q_ref = _inputs(cartpole, b, h)
    loss = _loss_fn(sim, q_ref)
    grads = _tape_gradients(loss, x)
    again = _tape_gradients(loss, x)  # the step buffers' gradients start from zero each backward pass: no leftovers
    for name in x:
        torch.testing.assert_close(again[name], grads[name], rtol=0, atol=1e-7)
    for name, value in x.items():
        fd = torch.zeros_like(value)
        for idx in np.ndindex(*value.shape):
            e = torch.zeros_like(value)
            e[idx] = EPS[name]
            fd[idx] = _shifted(loss, x, name, e) / (2 * EPS[name])
        assert fd.abs().max() > 1e-4, name  # the input really moves the loss
        err = float((grads[name] - fd).norm() / fd.norm())
        assert err < FD_RTOL, (name, err)


def test_step_diff_gradients_match_finite_differences_on_the_humanoid(humanoid):
    """The project humanoid (21 DoF, a deep tree) through SolverReplay, 3 steps: directional derivatives along
    random directions (every element by finite differences would take 170 rollouts)."""
    b, h = 1, 3
    sim = Simulator(humanoid, b, DT, solver="replay", requires_grad=True)
    x, q_ref = _inputs(humanoid, b, h, seed=1)
    loss = _loss_fn(sim, q_ref)
    grads = _tape_gradients(loss, x)
    gen = torch.Generator().manual_seed(0)
    for name, value in x.items():
        for _ in range(2):
            d = torch.randn(value.shape, generator=gen)
            d /= d.norm()
            fd = _shifted(loss, x, name, EPS[name] * d) / (2 * EPS[name])
            tape = float((grads[name] * d).sum())
            # relative to the gradient's norm: a random direction may be nearly orthogonal to the gradient
            assert abs(tape - fd) <= FD_RTOL * float(grads[name].norm()), (name, tape, fd)
        assert grads[name].abs().max() > 1e-4, name
