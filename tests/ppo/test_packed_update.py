"""The packed PPO update (:class:`wresdyn.ppo.packed_update.PackedPPO`) against rsl-rl's own on the same rollout,
bit for bit: in one process, and in two over gloo through torchrun (rsl-rl's multi-GPU PPO on the CPU)."""

import copy
import json
import os
import sys
from pathlib import Path

import pytest
import torch
from rsl_rl.algorithms import PPO

from wresdyn.config_fields import set_fields
from wresdyn.learn.residual import obs_stats
from wresdyn.ppo.packed_update import PackedPPO, next_learning_rate
from wresdyn.ppo.replay_env import ReplayEnv
from wresdyn.ppo.runner import make_runner
from wresdyn.ppo.trainer import runner_cfg

ROOT = Path(__file__).resolve().parents[2]
TESTS = Path(__file__).resolve().parents[1]
if str(TESTS) not in sys.path:  # run as torchrun's script: conftest's helpers
    sys.path.insert(0, str(TESTS))
from conftest import tiny_ppo_config as tiny, torchrun_two  # noqa: E402

KLS = (0.03, 1e-6, 10.0)
"""Targets of the adaptive rate: the default (the rate moves where the KL says), one that lowers it at every
mini-batch after the first, one that raises it at every mini-batch after the first (to its 1e-2 bound)."""


def test_host_learning_rate_follows_rsl_rls_rule():
    assert next_learning_rate(1e-3, True, False) == 1e-3 / 1.5
    assert next_learning_rate(1e-3, False, True) == 1e-3 * 1.5
    assert next_learning_rate(1e-3, False, False) == 1e-3
    assert next_learning_rate(1e-5, True, False) == 1e-5 and next_learning_rate(9e-3, False, True) == 1e-2


def _rollout(robot, trajs, rate_hz, tmp_path, desired_kl, seed=0, device="cpu"):
    """A runner of the tiny residual run (rsl-rl's PPO) on ``device`` after one rollout: its storage full, the
    returns computed."""
    torch.manual_seed(0)  # the same initial weights on every rank
    cfg = set_fields(tiny(), {"env.num_worlds": 8, "ppo.num_learning_epochs": 3, "ppo.desired_kl": desired_kl})
    mean, std = obs_stats(trajs)
    env = ReplayEnv(robot, trajs, rate_hz, 8, cfg.env, cfg.residual, cfg.rewards, obs_mean=mean, obs_std=std,
                    seed=seed, device=device)
    rcfg = runner_cfg(cfg)
    # the residual's default: the graph update, which is PackedPPO on the CPU
    assert rcfg["algorithm"]["class_name"] == "wresdyn.ppo.graph_update:GraphPPO"
    rcfg["algorithm"]["class_name"] = "PPO"
    runner = make_runner(env, rcfg, tmp_path)
    alg, obs = runner.alg, env.get_observations()
    torch.manual_seed(seed)  # a different rollout on each rank
    with torch.inference_mode():
        for _ in range(cfg.ppo.num_steps_per_env):
            obs, rew, dones, extras = env.step(alg.act(obs))
            alg.process_env_step(obs, rew, dones, extras)
        alg.compute_returns(obs)
    return alg


def _state(alg) -> list[torch.Tensor]:
    """Every number the update changes: weights, normalisers, Adam's moments and step counts."""
    out = [t.detach().clone() for t in (*alg.actor.state_dict().values(), *alg.critic.state_dict().values())]
    for s in alg.optimizer.state_dict()["state"].values():
        out += [torch.as_tensor(v).clone() for v in s.values()]
    return out


def compare(alg) -> dict:
    """rsl-rl's update and the packed one from the same state, storage and mini-batch order: whether the weights,
    optimiser state, learning rate and losses are equal bit for bit, and whether the update moved anything."""
    start = copy.deepcopy((alg.actor.state_dict(), alg.critic.state_dict(), alg.optimizer.state_dict(),
                           alg.learning_rate))
    before = [p.detach().clone() for p in (*alg.actor.parameters(), *alg.critic.parameters())]
    storage = copy.deepcopy(alg.storage)
    torch.manual_seed(1)  # the mini-batch permutation
    ref_losses = alg.update()
    ref, ref_lr = _state(alg), alg.learning_rate
    moved = max(float((p.detach() - b).abs().max())
                for p, b in zip((*alg.actor.parameters(), *alg.critic.parameters()), before))
    alg.actor.load_state_dict(start[0])
    alg.critic.load_state_dict(start[1])
    alg.optimizer.load_state_dict(start[2])
    alg.learning_rate, alg.storage = start[3], storage
    torch.manual_seed(1)
    alg.__class__ = PackedPPO  # the same algorithm object, its update swapped
    losses = alg.update()
    alg.__class__ = PPO
    got = _state(alg)
    return {"moved": moved,
            "equal": len(ref) == len(got) and all(torch.equal(r, g) for r, g in zip(ref, got)),
            "lr": [ref_lr, alg.learning_rate, start[3]], "losses": [ref_losses, losses]}


@pytest.mark.parametrize("desired_kl", KLS)
def test_packed_update_equals_rsl_rls_update_bit_for_bit(robot, data, tmp_path, desired_kl):
    r = compare(_rollout(robot, data.split("train"), data.rate_hz, tmp_path, desired_kl))
    assert r["moved"] > 1e-4  # the update moved the weights
    assert r["equal"]
    ref_lr, lr, lr0 = r["lr"]
    assert lr == ref_lr and lr != lr0  # the rate moved, the same way
    assert r["losses"][1] == r["losses"][0]


def test_packed_update_equals_rsl_rls_on_two_processes(tmp_path):
    """Two ranks over gloo, each its own rollout: the KL packed with the gradients, the rate adapted on every rank,
    against rsl-rl's KL all-reduce, rank 0's broadcast rate and the gradients' bucket."""
    torchrun_two(__file__, str(tmp_path))
    for rank in (0, 1):
        for kl in KLS:
            r = json.loads((tmp_path / f"rank{rank}_kl{kl}.json").read_text())
            assert r["moved"] > 1e-4 and r["equal"], (rank, kl, r)
            ref_lr, lr, lr0 = r["lr"]
            assert lr == ref_lr and lr != lr0, (rank, kl, r)
            assert r["losses"][1] == r["losses"][0], (rank, kl, r)


def _two_process_worker(out: Path) -> None:
    """One torchrun rank of the test above: rsl-rl's multi-process PPO over gloo (the runner starts the group)."""
    from wresdyn.data.dataset import load_dataset
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset(ROOT / "data" / "dataset.npz", robot=robot)
    rank = int(os.environ["RANK"])
    trajs = data.split("train")[:2]
    for kl in KLS:
        (out / f"run{rank}_{kl}").mkdir()
        alg = _rollout(robot, trajs, data.rate_hz, out / f"run{rank}_{kl}", kl, seed=rank)
        assert alg.is_multi_gpu and alg.gpu_world_size == 2
        (out / f"rank{rank}_kl{kl}.json").write_text(json.dumps(compare(alg)))
    # gloo's worker threads must be joined before the interpreter ends: a process that exits with its group alive
    # may abort ("terminate called without an active exception") after its results are written
    torch.distributed.barrier()
    torch.distributed.destroy_process_group()


if __name__ == "__main__":
    _two_process_worker(Path(sys.argv[1]))
