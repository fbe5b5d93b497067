"""The PPO update with one host synchronisation (:class:`wresdyn.ppo.update.OneSyncPPO`) against rsl-rl's own
on the same rollout, and a run trained with it, checkpointed and resumed by rsl-rl's update."""

import copy
import dataclasses
import json

import pytest
import torch

from wresdyn.config_fields import set_fields
from wresdyn.learn.residual import obs_stats
from wresdyn.ppo.replay_env import ReplayEnv
from wresdyn.ppo.runner import make_runner
from wresdyn.ppo.trainer import runner_cfg, train
from wresdyn.ppo.update import OneSyncPPO, adapt_learning_rate

from conftest import tiny_ppo_config as tiny


def test_device_learning_rate_follows_rsl_rls_rule():
    lr = torch.tensor(1e-3, dtype=torch.float64)
    for kl, want in ((0.1, 1e-3 / 1.5), (0.001, 1e-3 * 1.5), (0.0, 1e-3), (0.02, 1e-3)):
        assert float(adapt_learning_rate(lr, torch.tensor(kl), 0.03)) == pytest.approx(want, rel=1e-15)
    assert float(adapt_learning_rate(torch.tensor(1e-5, dtype=torch.float64), torch.tensor(1.0), 0.03)) == 1e-5
    assert float(adapt_learning_rate(torch.tensor(9e-3, dtype=torch.float64), torch.tensor(0.0), 0.03)) == 9e-3
    assert float(adapt_learning_rate(torch.tensor(9e-3, dtype=torch.float64), torch.tensor(1e-4), 0.03)) == 1e-2


def _rollout(robot, data, tmp_path, desired_kl):
    """A runner of the tiny residual run after one rollout (its storage full, the returns computed)."""
    torch.manual_seed(0)
    cfg = set_fields(tiny(), {"env.num_worlds": 8, "ppo.num_learning_epochs": 3, "ppo.desired_kl": desired_kl})
    trajs = data.split("train")
    mean, std = obs_stats(trajs)
    env = ReplayEnv(robot, trajs, data.rate_hz, 8, cfg.env, cfg.residual, cfg.rewards, obs_mean=mean, obs_std=std)
    rcfg = runner_cfg(cfg)
    rcfg["algorithm"]["class_name"] = "PPO"  # rsl-rl's own update the reference
    runner = make_runner(env, rcfg, tmp_path)
    alg, obs = runner.alg, env.get_observations()
    with torch.inference_mode():
        for _ in range(cfg.ppo.num_steps_per_env):
            obs, rew, dones, extras = env.step(alg.act(obs))
            alg.process_env_step(obs, rew, dones, extras)
        alg.compute_returns(obs)
    return alg


@pytest.mark.parametrize("desired_kl", [0.03, 1e-6])
def test_one_sync_update_equals_rsl_rls_update(robot, data, tmp_path, desired_kl):
    """The same rollout, the same mini-batch order: the same weights, losses and learning rate up to float rounding
    (Adam with the rate as a tensor rounds its step differently). ``desired_kl`` 1e-6 makes every mini-batch after
    the first lower the rate, so the device rule acts at each of the 3 x 2 steps."""
    alg = _rollout(robot, data, tmp_path, desired_kl)
    start = copy.deepcopy((alg.actor.state_dict(), alg.critic.state_dict(), alg.optimizer.state_dict()))
    before = [p.detach().clone() for p in (*alg.actor.parameters(), *alg.critic.parameters())]
    storage = copy.deepcopy(alg.storage)
    torch.manual_seed(1)  # the mini-batch permutation
    ref_losses = alg.update()
    ref = [p.detach().clone() for p in (*alg.actor.parameters(), *alg.critic.parameters())]
    ref_lr = alg.learning_rate
    alg.actor.load_state_dict(start[0])
    alg.critic.load_state_dict(start[1])
    alg.optimizer.load_state_dict(start[2])
    alg.learning_rate, alg.storage = 1e-3, storage
    torch.manual_seed(1)
    alg.__class__ = OneSyncPPO  # the same algorithm object, its update swapped
    losses = alg.update()
    got = [p.detach() for p in (*alg.actor.parameters(), *alg.critic.parameters())]
    assert max(float((r - b).abs().max()) for r, b in zip(ref, before)) > 1e-3  # the update moved the weights
    for r, g in zip(ref, got):
        torch.testing.assert_close(g, r, rtol=1e-5, atol=1e-6)
    assert alg.learning_rate == pytest.approx(ref_lr, rel=1e-12)
    if desired_kl < 1e-3:  # the first mini-batch meets the rollout's own policy (KL 0), the 5 others lower the rate
        assert ref_lr == pytest.approx(1e-3 / 1.5**5, rel=1e-9)
    assert losses == pytest.approx(ref_losses, rel=1e-5, abs=1e-7)


def test_a_one_sync_run_checkpoints_as_rsl_rl_and_resumes_with_its_update(robot, data, tmp_path):
    run = tmp_path / "run"
    cfg = set_fields(tiny(iterations=2), {"ppo.one_sync_update": True})
    s = train(data, robot, cfg, run)
    assert s["iterations_this_session"] == 2
    ckpt = torch.load(run / "model_1.pt", weights_only=True)
    assert all(type(g["lr"]) is float for g in ckpt["optimizer_state_dict"]["param_groups"])
    # rsl-rl's own update goes on from it (how a run updates may change on resume)
    s = train(data, robot, dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, iterations=3,
                                                                            one_sync_update=False)), run)
    assert s["iterations_this_session"] == 1
    assert json.loads((run / "config.json").read_text())["config"]["ppo"]["one_sync_update"] is False


def test_rsl_rls_options_reach_its_runner_config():
    from wresdyn.errors import WresdynError

    cfg = set_fields(tiny(), {"ppo.mixed_precision": True, "ppo.compile_mode": "default", "ppo.one_sync_update": True})
    rcfg = runner_cfg(cfg)
    assert rcfg["algorithm"]["use_mixed_precision"] is True and rcfg["torch_compile_mode"] == "default"
    assert rcfg["algorithm"]["class_name"] == "wresdyn.ppo.update:OneSyncPPO"
    plain = runner_cfg(tiny())  # the defaults: the graph update, rsl-rl's bit for bit on the CPU (test_graph_update.py)
    assert plain["algorithm"]["class_name"] == "wresdyn.ppo.graph_update:GraphPPO"
    assert plain["torch_compile_mode"] is None
    assert plain["algorithm"]["use_mixed_precision"] is False
    with pytest.raises(WresdynError, match="compile_mode"):
        set_fields(tiny(), {"ppo.compile_mode": "reduce-overhead"})
