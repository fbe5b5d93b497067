"""Replay environment at tiny sizes: resets from the recording, PD replay parity, residual kinds, runaway."""

import dataclasses

import numpy as np
import pytest
import torch

from wresdyn.learn.residual import ResidualConfig
from wresdyn.ppo.replay_env import ReplayEnv, ReplayEnvConfig


def make_env(robot, data, n=4, physics=None, **cfg):
    return ReplayEnv(robot, data.split("train"), data.rate_hz, n, ReplayEnvConfig(**cfg), physics=physics)


def test_worlds_start_in_the_recorded_state(robot, data):
    env = make_env(robot, data, horizon=8)
    bank = env.bank
    assert torch.equal(env.sim.q, bank.q[env.g])
    assert torch.equal(env.sim.qd, bank.qd[env.g])
    # each episode stays inside one trajectory and within the horizon
    traj = torch.searchsorted(bank.start, env.g, right=True) - 1
    assert (env.end <= bank.start[traj] + bank.length[traj] - 1).all()
    assert ((env.end - env.g) <= 8).all() and ((env.end - env.g) >= 1).all()
    obs = env.get_observations()
    assert obs["policy"].shape == (4, 4 * robot.n_dof)
    assert obs["critic"].shape == (4, 6 * robot.n_dof + 1)


def test_zero_residual_is_the_plain_newton_pd_replay(robot, data):
    from wresdyn.sim.rollout import replay

    env = make_env(robot, data, n=1, horizon=50)
    g0 = int(env.g[0])
    traj = int(torch.searchsorted(env.bank.start, env.g, right=True)[0]) - 1
    env.end[0] = env.bank.start[traj] + env.bank.length[traj] - 1  # no time-out (a reset) inside the steps
    steps = min(5, int(env.end[0]) - g0 - 1)
    assert steps >= 3
    for _ in range(steps):
        env.step(torch.zeros(1, robot.n_dof))
    cmd = env.bank.q_cmd[g0:g0 + steps].double().numpy()
    q, _ = replay(robot, cmd, env.bank.q[g0].double().numpy(), env.bank.qd[g0].double().numpy(), dt=env.dt,
                  solver=env.env_cfg.solver)
    # same solver, same float32 state: only the order of float operations may differ
    np.testing.assert_allclose(env.q[0].numpy(), q[-1], atol=1e-5)


def test_delta_action_equals_torque_of_the_same_authority(robot, data):
    # explicit PD: kp (q_cmd + d - q) = kp (q_cmd - q) + kp d, and the delta scale is the torque scale / kp
    envs = {}
    for kind in ("torque", "delta_action"):
        env = ReplayEnv(robot, data.split("train"), data.rate_hz, 2, ReplayEnvConfig(horizon=8),
                        ResidualConfig(kind=kind), seed=3)
        a = torch.linspace(-1.0, 1.0, robot.n_dof).repeat(2, 1)
        env.step(a)
        envs[kind] = env
    torch.testing.assert_close(envs["torque"].q, envs["delta_action"].q, atol=1e-6, rtol=0)


def test_a_diverging_world_is_reset_counted_and_hidden(robot, data):
    env = make_env(robot, data, horizon=8)
    ids = torch.tensor([1])
    env.sim.set_state(ids, torch.full((1, robot.n_dof), float("nan")), torch.zeros(1, robot.n_dof))
    obs, rew, dones, extras = env.step(torch.zeros(4, robot.n_dof))
    assert env.diverged_total == 1
    assert dones[1] == 1 and not extras["time_outs"][1]
    assert rew[1] == 0.0 and torch.isfinite(rew).all()
    assert all(torch.isfinite(v).all() for v in obs.values())
    # the reset world is back on the recording
    assert torch.equal(env.sim.q[1], env.bank.q[env.g[1]])
    assert extras["log"]["Env/diverged"] == 1.0


def test_runaway_from_the_recording_is_reset(robot, data):
    env = make_env(robot, data, horizon=8, max_error=0.05)
    q = env.bank.q[env.g[:1]] + 0.2
    env.sim.set_state(torch.tensor([0]), q, env.bank.qd[env.g[:1]])
    env.step(torch.zeros(4, robot.n_dof))
    assert env.diverged_total == 1


def test_episodes_time_out_at_the_horizon(robot, data):
    env = make_env(robot, data, horizon=3)
    seen_timeout = False
    for _ in range(6):
        _, _, dones, extras = env.step(torch.zeros(4, robot.n_dof))
        seen_timeout |= bool(extras["time_outs"].any())
        assert torch.equal(dones.bool(), extras["time_outs"])  # nothing diverges at zero residual
        assert (env.episode_length_buf <= 3).all()
    assert seen_timeout and env.diverged_total == 0


def test_config_is_frozen():
    with pytest.raises(dataclasses.FrozenInstanceError):
        ReplayEnvConfig().horizon = 3


def test_observation_noise_reaches_the_policy_only(robot, data):
    n = robot.n_dof
    clean = make_env(robot, data, n=64, horizon=8).get_observations()
    assert torch.equal(clean["policy"], clean["critic"][:, :4 * n])
    noisy = make_env(robot, data, n=64, horizon=8, obs_noise=0.1).get_observations()
    diff = noisy["policy"] - noisy["critic"][:, :4 * n]
    assert 0.08 < float(diff.std()) < 0.12  # noise of 0.1 normalising std on the policy's view


def test_identified_physics_sets_the_model_and_the_command_delay(robot, data):
    """`env.physics` (the hybrid): the worlds step with the file's gains and friction and its delayed commands,
    exactly as a simulator given the same physics and a bank with the same delay."""
    from wresdyn.sim import Simulator, TrajectoryBank
    from wresdyn.sim.physics import PhysicalParams

    p = PhysicalParams.nominal(robot)
    p.kp, p.friction = 0.6 * p.kp, p.friction + 0.05 * p.effort
    p.delay = np.full(robot.n_dof, 1.5 / data.rate_hz)
    env = make_env(robot, data, n=1, horizon=50, physics=p)
    plain = make_env(robot, data, n=1, horizon=50)
    g0 = int(env.g[0])
    traj = int(torch.searchsorted(env.bank.start, env.g, right=True)[0]) - 1
    env.end[0] = env.bank.start[traj] + env.bank.length[traj] - 1  # no time-out (a reset) inside the steps
    plain._reset(torch.tensor([0]))
    plain.g[0], plain.end[0] = g0, env.end[0]
    plain.q[0], plain.qd[0] = env.bank.q[g0], env.bank.qd[g0]
    plain.sim.set_state(torch.tensor([0]), env.bank.q[g0:g0 + 1], env.bank.qd[g0:g0 + 1])
    steps = min(8, int(env.end[0]) - g0 - 1)
    assert steps >= 3
    for _ in range(steps):
        env.step(torch.zeros(1, robot.n_dof))
        plain.step(torch.zeros(1, robot.n_dof))
    sim = Simulator(robot, 1, env.dt, solver=env.env_cfg.solver)
    sim.set_physics(p)
    bank = TrajectoryBank(data.split("train"), sim.device, torch.full((robot.n_dof,), 1.5))
    sim.set_state(torch.tensor([0]), bank.q[g0:g0 + 1], bank.qd[g0:g0 + 1])
    for k in range(steps):
        q, _ = sim.step(bank.target(torch.tensor([g0 + k])), None)
    torch.testing.assert_close(env.q, q, atol=1e-6, rtol=0)
    assert (env.q - plain.q).abs().max() > 1e-4  # the physics file matters
