"""Multiple shooting in identification (:mod:`wresdyn.identify.shooting`): a chain of windows whose free start states sit
on the simulated path is the single long window, and its gradient in the physics and the free states agrees with
central differences. A 3-link servo robot (``tests/sim/test_servo.py``'s, goal profile on), tiny sizes."""

import sys
from pathlib import Path

import numpy as np
import pytest
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "sim"))
from test_servo import make_robot  # noqa: E402

from conftest import check_directional_gradients  # noqa: E402
from wresdyn.identify.shooting import ShootingNodes, chain_loss, draw_chains  # noqa: E402
from wresdyn.identify.sysid import NonFiniteLoss, SysIdConfig, _non_finite  # noqa: E402
from wresdyn.learn.window_fit import squared_error  # noqa: E402
from wresdyn.sim import Simulator, TrajectoryBank, rollout  # noqa: E402
from wresdyn.sim.physics import PhysicsModel  # noqa: E402

DT = 0.002
B, K, H = 2, 3, 4
"""Chains, windows per chain, steps per window."""


def recordings(n: int = 3, t_len: int = 40):
    """Runs of commands stepping every 10 samples, with a made-up 'recording' near them (the loss only compares)."""
    rng = np.random.default_rng(1)
    runs = []
    for _ in range(2):
        cmd = np.repeat(rng.uniform(-0.3, 0.3, (t_len // 10, n)), 10, axis=0)
        q = cmd + rng.normal(0.0, 0.02, cmd.shape)
        runs.append(type("T", (), {"q": q, "qd": rng.normal(0.0, 0.1, cmd.shape), "qdd": np.zeros_like(cmd),
                                   "q_cmd": cmd})())
    return runs


@pytest.fixture(scope="module")
def problem(tmp_path_factory):
    robot = make_robot(tmp_path_factory.mktemp("shoot"), joints="*")
    cfg = SysIdConfig(shooting=K, windows=B, horizon_curriculum=(H,), fit=("kp", "damping", "deadband"))
    model = PhysicsModel(robot, fit=cfg.fit, dt=DT)
    bank = TrajectoryBank(recordings(), "cpu", 0.0, model.goal_accel_steps().float())
    nodes = ShootingNodes(bank, H)
    traj, first = draw_chains(bank, np.random.default_rng(0), B, K, H, H)
    sim = Simulator(robot, B * K, DT, solver="replay", requires_grad=True, param_grads=True)
    return robot, cfg, model, bank, nodes, traj, first, sim


def test_chain_without_defects_is_the_long_window(problem):
    robot, cfg, model, bank, nodes, traj, first, sim = problem
    long_sim = Simulator(robot, B, DT, solver="replay", requires_grad=True, param_grads=True)
    window = bank.window(torch.as_tensor(traj), torch.as_tensor(first), K * H)
    long_sim.set_physics(model())
    run = rollout(long_sim, window, grad=True)
    long_loss = cfg.w_q * squared_error(run.q[:, 1:], window.q[:, 1:]) \
        + cfg.w_qd * squared_error(run.qd[:, 1:], window.qd[:, 1:])
    with torch.no_grad():  # the free states put where the long window passes
        for k in range(1, K):
            idx = torch.as_tensor(nodes.index(traj, first + k * H))
            nodes.states.weight[idx] = torch.cat([run.q[:, k * H], run.qd[:, k * H]], -1).detach()
    loss, parts = chain_loss(cfg, model, sim, bank, nodes, traj, first, H)
    assert parts["defect"] < 1e-12, parts
    # the same float32 steps from the same states: equal up to the order of the mean's sums
    assert float(loss.detach()) == pytest.approx(float(long_loss.detach()), rel=1e-6)
    # recorded starts instead: defects the penalty sees
    nodes_rec = ShootingNodes(bank, H)
    _, parts_rec = chain_loss(cfg, model, sim, bank, nodes_rec, traj, first, H)
    assert parts_rec["defect"] > 1e-4, parts_rec


def test_chain_gradient_matches_central_differences(problem):
    robot, cfg, model, bank, nodes, traj, first, sim = problem
    cfg = type(cfg)(**{**cfg.__dict__, "w_defect": 10.0})

    def loss():
        return chain_loss(cfg, model, sim, bank, nodes, traj, first, H)[0]

    model.zero_grad()
    nodes.zero_grad()
    loss().backward()
    params = {k: p for k, p in model.named_parameters() if p.requires_grad}
    grads = {k: p.grad.clone() for k, p in params.items()}
    # the free states of the drawn chains' later windows (a sparse gradient, densified)
    used = torch.as_tensor(np.stack([nodes.index(traj, first + k * H) for k in range(1, K)]).reshape(-1))
    dense = nodes.states.weight.grad.to_dense()
    assert dense[used].abs().max() > 0 and dense.abs().sum() == dense[used].abs().sum()
    free = torch.nn.Parameter(nodes.states.weight.data[used].clone())

    def node_loss():
        with torch.no_grad():
            nodes.states.weight[used] = free
        return loss()

    check_directional_gradients(loss, params, grads, eps=1e-2)
    check_directional_gradients(node_loss, {"nodes": free}, {"nodes": dense[used]}, eps=1e-3)


def test_shooting_config_checks_and_non_finite_error():
    with pytest.raises(ValueError, match="multiple of the shortest"):
        SysIdConfig(shooting=2, horizon_curriculum=(16, 24))
    SysIdConfig(shooting=1, horizon_curriculum=(16, 24))  # independent windows: any lengths
    err = _non_finite(7, ("kp", "goal_accel"))
    assert isinstance(err, NonFiniteLoss) and "goal_accel" in str(err) and "\n" not in str(err)
    assert "--delay-grid" in str(_non_finite(7, ("delay",)))
    assert isinstance(_non_finite(7, ("kp",)), FloatingPointError)


def test_identify_with_a_shooting_pool_runs_and_moves_the_free_states(problem):
    """A few identification steps with chains from a pool: the free states of the drawn nodes move, the others stay."""
    from wresdyn.identify.sysid import IdentifyLearner

    robot, _, _, bank, _, _, _, _ = problem
    runs = recordings()
    ds = type("D", (), {"split": lambda self, s: runs if s == "train" else [], "fit_weights": lambda self: np.ones(3),
                        "excluded_joints": [], "rate_hz": 1.0 / DT})()
    cfg = SysIdConfig(shooting=K, shooting_pool=3, windows=B, horizon_curriculum=(H,), iterations=4,
                      fit=("kp", "damping"), shooting_lr=1e-2)
    learner = IdentifyLearner(robot, ds, cfg, None, np.random.default_rng(0), runs, DT, lambda *_: None, None)
    before = learner.nodes.states.weight.detach().clone()
    for it in range(4):
        parts, _ = learner.step(it, H, cfg.lr)
        assert np.isfinite(parts["loss"]) and parts["defect"] >= 0.0
    moved = (learner.nodes.states.weight.detach() != before).any(-1)
    pool = learner.pool[1]
    used = {int(i) for k in range(1, K) for i in learner.nodes.index(pool[0], pool[1] + k * H)}
    assert moved.any() and set(np.flatnonzero(moved.numpy()).tolist()) <= used
