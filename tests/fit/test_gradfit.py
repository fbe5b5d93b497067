"""Gradient fit through the differentiable Warp simulation: network-parameter gradients vs central finite
differences, a fit that reduces the replay error, and checkpoint/resume. (The simulator's own gradients w.r.t.
state, target and torque: tests/sim/test_sim.py.)"""

import dataclasses

import numpy as np
import pytest
import torch

from wresdyn.data.mismatch import Mismatch
from wresdyn.fit.gradfit import GradFitConfig, build_policy, fit, window_loss
from wresdyn.learn.residual import ResidualConfig, obs_stats
from wresdyn.learn.runs import RunError
from wresdyn.sim import Simulator, TrajectoryBank, rollout

DT = 0.002
FD_RTOL = 3e-2
"""Error allowed between the tape's directional derivative and a central difference, relative to the gradient's
norm: the simulation runs in float32, so a central difference with step eps carries ~1e-7·|L|/eps round-off."""

REAL = Mismatch(friction=0.02, damping=0.4, kp_scale=0.9, kd_scale=1.2)
"""The real robot of these tests: dry friction of 2 % of each effort limit (1.6 N*m on the quadruped), extra
viscous damping of 0.4 kd, 0.9x kp and 1.2x kd; recorded at the sample rate, no delay, saturation or noise."""


@pytest.mark.parametrize("kind", ["torque", "delta_action"])
def test_gradient_wrt_network_parameters_matches_finite_differences(cartpole, record, kind):
    torch.manual_seed(0)
    # no dry friction: 2 % of the cartpole URDF's effort limit of 1000 would hold its 20 N*m/rad poles still
    data = record(cartpole, dataclasses.replace(REAL, friction=0.0), {"train": 2}, seconds=0.4)
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
    assert g.norm() > 1e-4  # the parameters really move the loss
    eps = 1e-3  # small enough not to cross the action clamp's kinks

    def shifted(direction, sign):
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

    # along the gradient (its size and sign) and along a random direction (the rest of it); the error is relative
    # to |g|, since a random direction in ~300 parameters may be nearly orthogonal to the gradient
    random = torch.randn(g.shape, generator=torch.Generator().manual_seed(0))
    for direction in (g / g.norm(), random / random.norm()):
        fd = (shifted(direction, 1.0) - shifted(direction, -1.0)) / (2 * eps)
        analytic = float(g @ direction)
        assert abs(analytic - fd) <= FD_RTOL * float(g.norm()), (analytic, fd)


def test_fit_reduces_replay_error_and_resumes(tmp_path, quadruped, record):
    data = record(quadruped, REAL, {"train": 3, "validation": 1}, seconds=0.3, amplitude=0.4)
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


def test_interrupted_fit_resumes_to_the_same_policy(tmp_path, quadruped, record):
    """Stopping at ``until`` and resuming gives the uninterrupted run's parameters exactly: the checkpoint carries
    the optimiser, the window sampler, the observation-noise generator and the best residual on validation so far."""
    data = record(quadruped, REAL, {"train": 2, "validation": 1}, seconds=0.3, amplitude=0.4)
    cfg = GradFitConfig(residual=ResidualConfig(hidden_dims=(16,)), horizon=4, horizon_curriculum=(), windows=4,
                        iterations=6, obs_noise=0.1, solver="featherstone", select_every=1)
    straight, _ = fit(quadruped, data, cfg, log=lambda *_: None)
    fit(quadruped, data, cfg, out=tmp_path, log=lambda *_: None, until=3)
    resumed, _ = fit(quadruped, data, cfg, out=tmp_path, log=lambda *_: None)
    for a, b in zip(straight.state_dict().values(), resumed.state_dict().values()):
        assert torch.equal(a, b)
    noiseless, _ = fit(quadruped, data, dataclasses.replace(cfg, obs_noise=0.0), log=lambda *_: None)
    assert not torch.equal(next(iter(noiseless.parameters())), next(iter(straight.parameters())))


def test_the_fit_takes_physics_as_parameters_and_refuses_a_path_alone(tmp_path, quadruped, record):
    """Physics travel as :class:`PhysicalParams`: the fit steps with them and the run carries them; ``cfg.physics``
    only records where they came from, so a config naming a file with no parameters given is refused, not ignored."""
    from wresdyn.fit.gradfit import export_run
    from wresdyn.sim.physics import PhysicalParams

    data = record(quadruped, REAL, {"train": 2, "validation": 1}, seconds=0.3, amplitude=0.4)
    cfg = GradFitConfig(residual=ResidualConfig(hidden_dims=(16,)), horizon=4, horizon_curriculum=(), windows=2,
                        iterations=2, solver="featherstone", physics="elsewhere/physics.json")
    with pytest.raises(ValueError, match="elsewhere/physics.json"):
        fit(quadruped, data, cfg, log=lambda *_: None)
    physics = PhysicalParams.nominal(quadruped)
    physics.kp = physics.kp * 0.5
    lines = []
    policy, _ = fit(quadruped, data, cfg, out=tmp_path, log=lines.append, physics=physics)
    assert any(ln.startswith("validation at the start: ") for ln in lines)  # the identified model alone, a candidate
    export_run(policy, tmp_path, cfg, data, physics=physics)
    assert PhysicalParams.load(tmp_path / "physics.json", quadruped).kp.tolist() == physics.kp.tolist()


def test_parametric_baseline_fits_friction_and_gains(quadruped, record):
    """The real quadruped (:data:`REAL`) has extra dry friction and damping and 0.9x kp / 1.2x kd. Fitted through
    SolverReplay, the default solver, whose implicit drive damping is the real robot's integration scheme."""
    torch.manual_seed(0)
    data = record(quadruped, REAL, {"train": 3, "validation": 1}, seconds=0.6, amplitude=0.4)
    # 160 Adam steps of 0.1: long enough for the softplus friction to travel the 8x from its start to the truth
    cfg = GradFitConfig(model="parametric", horizon=16, horizon_curriculum=(), windows=8, iterations=160, lr=0.1,
                        solver="replay")
    train = data.split("train")
    sim = Simulator(quadruped, 8, DT, solver="replay")
    w = TrajectoryBank(train, sim.device).sample(np.random.default_rng(5), 8, 16)

    def error(policy):
        with torch.no_grad():
            return float((rollout(sim, w, policy).q[:, 1:] - w.q[:, 1:]).abs().mean())

    start = build_policy(quadruped, cfg.residual, *obs_stats(train), model="parametric")
    policy, _ = fit(quadruped, data, cfg, log=lambda *_: None)
    found = {k: float(v.mean()) for k, v in policy.parameters_physical().items()}
    kd = float(quadruped.kd.mean())
    true_friction = REAL.friction * float(np.mean(quadruped.effort))  # 1.6 N*m, 8x the start
    true_viscous = (REAL.kd_scale + REAL.damping) * kd  # drive damping and extra damping, as the fit can split them
    # measured: error 0.086x the start's; friction 0.76 of the truth (the smooth tanh law against MuJoCo's soft
    # frictionloss), viscous 0.89, kp_scale 0.82 (truth 0.9). The bounds leave room for float32 differences between
    # machines and fail a fit that stops short (80 steps of 3e-2 reach 0.22 of the friction).
    assert error(policy) < 0.15 * error(start)
    assert 0.6 < found["friction"] / true_friction < 1.2, found
    assert 0.75 < (found["kd_scale"] * kd + found["damping"]) / true_viscous < 1.15, found
    assert 0.7 < found["kp_scale"] < 0.97, found  # the real drives are 0.9x as stiff


def test_recorded_torques_never_reach_the_fit(quadruped, record):
    """The same recording with every torque NaN fits to exactly the same residual and curve: the gradient fit reads
    joint states and commands only. (Dataset.validate refuses NaN; the learners never call it.)"""
    data = record(quadruped, REAL, {"train": 2, "validation": 1}, seconds=0.2, amplitude=0.4)
    assert all(t.tau is not None and np.isfinite(t.tau).all() for t in data.trajectories)
    nan = dataclasses.replace(data, trajectories=[dataclasses.replace(t, tau=np.full_like(t.q, np.nan))
                                                  for t in data.trajectories])
    cfg = GradFitConfig(residual=ResidualConfig(hidden_dims=(16,)), horizon=4, horizon_curriculum=(), windows=4,
                        iterations=4, select_every=2)
    (a, curve_a), (b, curve_b) = (fit(quadruped, d, cfg, log=lambda *_: None) for d in (data, nan))
    assert a.state_dict().keys() == b.state_dict().keys()
    assert all(torch.equal(a.state_dict()[k], b.state_dict()[k]) for k in a.state_dict())
    drop_wall = lambda curve: [{k: v for k, v in row.items() if k != "wall"} for row in curve]  # noqa: E731
    assert drop_wall(curve_a) == drop_wall(curve_b) and np.isfinite(curve_a[-1]["validation"])
