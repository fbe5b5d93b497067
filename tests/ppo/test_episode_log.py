"""The deferred episode bookkeeping (:mod:`wresdyn.ppo.episode_log`, ``ppo.deferred_episode_log``) against rsl-rl's
per-step one: the same weights bit for bit after training and the same logged episode rewards and lengths, in one
process and in two over gloo through torchrun; and its default, on where the run's device is CUDA."""

import json
import os
import sys
from pathlib import Path

import torch

from wresdyn.config_fields import set_fields
from wresdyn.learn.residual import obs_stats
from wresdyn.ppo.episode_log import flush_episode_log
from wresdyn.ppo.ppo_config import RESUME_MAY_CHANGE, PPOConfig
from wresdyn.ppo.replay_env import ReplayEnv
from wresdyn.ppo.runner import make_runner, seed_processes
from wresdyn.ppo.trainer import runner_cfg, train

ROOT = Path(__file__).resolve().parents[2]
TESTS = Path(__file__).resolve().parents[1]
if str(TESTS) not in sys.path:  # run as torchrun's script: conftest's helpers
    sys.path.insert(0, str(TESTS))
from conftest import tiny_ppo_config as tiny, torchrun_two  # noqa: E402

ITERATIONS = 3


def _train(robot, trajs, rate_hz, run_dir, deferred: bool, rank: int = 0) -> dict:
    """A tiny residual run of :data:`ITERATIONS` iterations: its final state and what rank 0 logged of episodes."""
    cfg = set_fields(tiny(), {"env.num_worlds": 8, "ppo.deferred_episode_log": deferred})
    seed_processes(cfg.ppo.seed + rank, 1)
    torch.manual_seed(0)  # the same initial weights on every rank
    mean, std = obs_stats(trajs)
    env = ReplayEnv(robot, trajs, rate_hz, 8, cfg.env, cfg.residual, cfg.rewards, obs_mean=mean, obs_std=std,
                    seed=rank)
    rcfg = runner_cfg(cfg)
    run_dir.mkdir(parents=True)
    assert rcfg.get("deferred_episode_log", False) is deferred
    runner = make_runner(env, rcfg, run_dir, rank == 0)
    torch.manual_seed(1 + rank)  # a different rollout on each rank
    runner.learn(ITERATIONS)
    alg, logger = runner.alg, runner.logger
    assert hasattr(logger, "_pending_episodes") is deferred
    flush_episode_log(logger)  # nothing left: each iteration's log flushed it
    state = [t.detach().clone() for t in (*alg.actor.state_dict().values(), *alg.critic.state_dict().values())]
    for s in alg.optimizer.state_dict()["state"].values():
        state += [torch.as_tensor(v).clone() for v in s.values()]
    return {"state": state, "lr": alg.learning_rate, "rewards": list(logger.rewbuffer),
            "lengths": list(logger.lenbuffer), "cur": logger.cur_reward_sum.tolist()}


def compare(robot, trajs, rate_hz, out: Path, rank: int = 0) -> dict:
    ref = _train(robot, trajs, rate_hz, out / f"rsl{rank}", False, rank)
    got = _train(robot, trajs, rate_hz, out / f"deferred{rank}", True, rank)
    return {"equal": len(ref["state"]) == len(got["state"])
            and all(torch.equal(a, b) for a, b in zip(ref["state"], got["state"])),
            "lr": [ref["lr"], got["lr"]], "episodes": len(ref["rewards"]),
            "logged_equal": all(ref[k] == got[k] for k in ("rewards", "lengths", "cur"))}


def test_deferred_episode_log_learns_and_logs_the_same(robot, data, tmp_path):
    r = compare(robot, data.split("train"), data.rate_hz, tmp_path)
    assert r["equal"] and r["lr"][0] == r["lr"][1]
    assert r["episodes"] > 0 and r["logged_equal"]


def test_deferred_episode_log_on_two_processes(tmp_path):
    torchrun_two(__file__, str(tmp_path))
    for rank in (0, 1):
        r = json.loads((tmp_path / f"rank{rank}.json").read_text())
        assert r["equal"] and r["lr"][0] == r["lr"][1], (rank, r)
        if rank == 0:  # the rank that logs
            assert r["episodes"] > 0 and r["logged_equal"], r


def test_deferred_by_default_on_cuda_only():
    """``None`` resolves by the device string alone (no GPU needed): on for ``cuda`` and ``cuda:N``, off for ``cpu``;
    ``True``/``False`` win on either."""
    assert PPOConfig().deferred_episode_log is None and "deferred_episode_log" in RESUME_MAY_CHANGE
    for device, forced, on in (("cpu", None, False), ("cuda", None, True), ("cuda:0", None, True),
                               ("cpu", True, True), ("cuda:0", False, False)):
        assert PPOConfig(device=device, deferred_episode_log=forced).defers_episode_log() is on, (device, forced)
        cfg = set_fields(tiny(), {"ppo.device": device, "ppo.deferred_episode_log": forced})
        assert runner_cfg(cfg).get("deferred_episode_log", False) is on, (device, forced)


def test_a_run_that_recorded_false_resumes_with_the_default(robot, data, tmp_path):
    """A run folder of before the default (``config.json``: ``false``) goes on with ``None``, and the reverse."""
    run = tmp_path / "run"
    train(data, robot, set_fields(tiny(), {"ppo.iterations": 1, "ppo.deferred_episode_log": False}), run)
    assert json.loads((run / "config.json").read_text())["config"]["ppo"]["deferred_episode_log"] is False
    assert train(data, robot, set_fields(tiny(), {"ppo.iterations": 2}), run)["iterations_this_session"] == 1
    assert json.loads((run / "config.json").read_text())["config"]["ppo"]["deferred_episode_log"] is None
    forced = set_fields(tiny(), {"ppo.iterations": 3, "ppo.deferred_episode_log": False})
    assert train(data, robot, forced, run)["iterations_this_session"] == 1


def _two_process_worker(out: Path) -> None:
    """One torchrun rank of the test above: rsl-rl's multi-process PPO over gloo (the runner starts the group)."""
    from wresdyn.data.dataset import load_dataset
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset(ROOT / "data" / "dataset.npz", robot=robot)
    rank = int(os.environ["RANK"])
    r = compare(robot, data.split("train")[:2], data.rate_hz, out, rank)
    (out / f"rank{rank}.json").write_text(json.dumps(r))
    torch.distributed.barrier()
    torch.distributed.destroy_process_group()


if __name__ == "__main__":
    _two_process_worker(Path(sys.argv[1]))
