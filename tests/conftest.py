"""Shared fixtures: robots loaded once per test session, and tiny datasets recorded on the real robot.

Every dataset of the tests is recorded by :mod:`wresdyn.data.real_robot`, the package's simulated real robot:
the humanoid through :func:`~wresdyn.data.real_robot.collect` (the paper's excitation, IK included), robots without
sole sites (quadruped, cartpole) by :meth:`~wresdyn.data.real_robot.RealRobot.record` driven by the package's
check command :func:`wresdyn.sim.parity.multisine_command`.
"""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

# The suite's parallelism is its worker processes, one per core (scripts/test.sh), so a test and every command it
# starts compute on one thread: a second one waits on a core the other worker holds (torch's threads spin while they
# wait), which made the deploy test 1.6x slower beside one busy core and 4x slower beside another deploy test.
os.environ.setdefault("OMP_NUM_THREADS", "1")

QUADRUPED_GAINS = {"joint": [{"match": "*", "kp": 80.0, "kd": 2.0, "armature": 0.02}]}
"""Gains for newton's quadruped.urdf, which has none (same as examples/gains/quadruped.toml, inline)."""

LEARNER_COUNTS = {"train": 2, "validation": 1, "heldout": 1, "ood": 1}
"""Trajectories per split of the learner tests' recordings: every split a learner or the evaluation reads."""


def tiny_ppo_config(arch="mlp", iterations=2, kind="torque"):
    """A PPO residual configuration at rsl_rl's test sizes (4 envs, 8 steps, 32-unit nets), for the PPO tests."""
    from wresdyn.ppo.ppo_config import PPOConfig, TrainConfig
    from wresdyn.ppo.replay_env import ReplayEnvConfig
    from wresdyn.learn.residual import ResidualConfig

    return TrainConfig(
        env=ReplayEnvConfig(num_worlds=4, horizon=8),
        residual=ResidualConfig(kind=kind, arch=arch, hidden_dims=(32, 32), critic_hidden_dims=(32, 32),
                                gru_hidden_dim=32),
        ppo=PPOConfig(num_steps_per_env=8, iterations=iterations, save_interval=1, num_mini_batches=2,
                      num_learning_epochs=2),
    )


def torchrun_two(script: str, *args: str) -> None:
    """``script`` as a worker on two processes under torchrun (gloo on the CPU), one thread each, the repository and
    the script's folder on the path; fails the test with the workers' error output if either exits non-zero."""
    root = Path(__file__).resolve().parent.parent
    path = os.pathsep.join([str(root), str(Path(script).parent), os.environ.get("PYTHONPATH", "")])
    env = dict(os.environ, OMP_NUM_THREADS="1", PYTHONPATH=path)
    res = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
                          str(script), *args], capture_output=True, text=True, env=env, timeout=600, cwd=root)
    assert res.returncode == 0, res.stderr[-3000:]


def check_directional_gradients(loss, params: dict, grads: dict, eps: float, rtol: float = 2e-2) -> None:
    """Each parameter's gradient ``grads[name]`` against a central difference of ``loss()`` along one random unit
    direction (seeded): every field must move the loss, and the two slopes agree within ``rtol`` of the gradient's norm."""
    import torch

    gen = torch.Generator().manual_seed(0)
    for name, p in params.items():
        d = torch.randn(p.shape, generator=gen, dtype=p.dtype)
        d /= d.norm()
        with torch.no_grad():
            p.add_(eps * d)
            plus = float(loss())
            p.sub_(2 * eps * d)
            minus = float(loss())
            p.add_(eps * d)
        fd = (plus - minus) / (2 * eps)
        tape = float((grads[name] * d).sum())
        assert grads[name].abs().max() > 1e-5, name  # the field really moves the loss
        assert abs(tape - fd) <= rtol * float(grads[name].norm()) + 1e-6, (name, tape, fd)


def pytest_addoption(parser):
    parser.addoption("--run-slow", action="store_true", help="also run tests marked slow")
    parser.addoption("--run-browser", action="store_true",
                     help="also run tests marked browser (they need Chromium on PATH)")


def pytest_collection_modifyitems(config, items):
    for marker, option in (("slow", "--run-slow"), ("browser", "--run-browser")):
        if config.getoption(option):
            continue
        skip = pytest.mark.skip(reason=f"{marker}: opt in with {option}")
        for item in items:
            if marker in item.keywords:
                item.add_marker(skip)


@pytest.fixture(scope="session", autouse=True)
def foot_workspace_once():
    """The foot workspace of a robot, sampled once per test process for each IK, excitation configuration and seed,
    and handed out as copies: every :func:`~wresdyn.data.real_robot.collect` of the humanoid samples the same one
    (its own seeded generator, 400 IK solves: seconds each time). A caller that asks for the sampling's progress
    lines (``wresdyn collect``) gets the sampling itself."""
    import copy

    from wresdyn.data import excitation

    sample, done = excitation.foot_workspace, {}

    def once(ik, cfg, seed=0, progress=None):
        key = (id(ik.robot), ik.frames, ik.config, cfg, seed)
        try:
            hash(key)
        except TypeError:  # an unhashable configuration: sampled as it comes
            key = None
        if progress is not None or key is None:
            return sample(ik, cfg, seed, progress)
        if key not in done:  # the robot kept with its workspace: its id is not reused
            done[key] = (sample(ik, cfg, seed), ik.robot)
        return copy.deepcopy(done[key][0])

    excitation.foot_workspace = once
    yield
    excitation.foot_workspace = sample


@pytest.fixture(autouse=True)
def one_torch_thread():
    """Each test starts on one torch thread (as above): a learner that pins more (the skills' PPO pins 2 unless told)
    would otherwise keep them for the worker's later tests."""
    import torch

    torch.set_num_threads(1)


@pytest.fixture(scope="session")
def humanoid():
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    return load_robot(DEFAULT_ROBOT)


@pytest.fixture(scope="module")
def floating(humanoid):
    """The humanoid with a floating base (the floor plants' robot)."""
    from wresdyn.robot.description import load_robot

    return load_robot(humanoid.source, base="floating")


@pytest.fixture(scope="session")
def robot(humanoid):
    """The robot of the learner tests (replay env, PPO, evaluation): the project humanoid."""
    return humanoid


@pytest.fixture(scope="session")
def shipped_mismatch():
    """The shipped benchmark's real robot (data/mismatch_default.toml): friction, gains, delay, saturation, noise."""
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.paths import DEFAULT_MISMATCH

    return Mismatch.load(DEFAULT_MISMATCH)


@pytest.fixture(scope="session")
def data(humanoid, shipped_mismatch):
    """A tiny recording of the humanoid on the shipped real robot by ``wresdyn collect``'s code: 2 train,
    1 validation, 1 held-out, 1 OOD trajectory of 0.2 s."""
    from wresdyn.data.real_robot import collect

    return collect(humanoid, shipped_mismatch, LEARNER_COUNTS, duration=0.2)


@pytest.fixture(scope="session")
def quadruped():
    from wresdyn.robot.description import load_robot

    return load_robot("newton:quadruped.urdf", gains=QUADRUPED_GAINS)


@pytest.fixture(scope="session")
def cartpole():
    from wresdyn.robot.description import load_robot

    return load_robot("newton:cartpole.urdf", gains="examples/gains/cartpole.toml")


def record_multisine(robot, mismatch, counts: dict, seconds: float, amplitude: float = 0.2, rate_hz: float = 500.0,
                     seed: int = 0):
    """A :class:`~wresdyn.data.dataset.Dataset` recorded on ``RealRobot(robot, mismatch)``: per split in ``counts``,
    that many :func:`~wresdyn.sim.parity.multisine_command` commands of ``seconds`` (``amplitude`` of each joint's
    half-range; out-of-distribution 1.5x larger), each with its own seed. Stored as ``collect`` stores: float32
    states, q̈ by :func:`~wresdyn.data.dataset.derive_qdd`, the diagnostic torque kept."""
    from wresdyn.data.dataset import Dataset, Trajectory, derive_qdd
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.sim.parity import multisine_command

    real = RealRobot(robot, mismatch, rate_hz)
    f32 = lambda a: np.asarray(a, dtype=np.float32).astype(np.float64)  # noqa: E731
    trajs = []
    for s, (split, count) in enumerate(counts.items()):
        amp = 1.5 * amplitude if split == "ood" else amplitude
        for i in range(count):
            q_cmd = f32(multisine_command(robot, seconds, 1.0 / rate_hz, amp, seed=1000 * seed + 100 * s + i))
            q, qd, tau = real.record(q_cmd, np.random.default_rng([seed, s, i]))
            q, qd = f32(q), f32(qd)
            trajs.append(Trajectory(f"{split}_{i:03d}", split, np.arange(len(q_cmd)) / rate_hz, q, qd,
                                    derive_qdd(qd, rate_hz), q_cmd, f32(tau)))
    return Dataset(list(robot.joint_names), rate_hz, trajs, str(robot.source), robot.source_sha256, mismatch.to_dict(),
                   seed, {"generator": "RealRobot.record of wresdyn.sim.parity.multisine_command"})


@pytest.fixture(scope="session")
def record():
    """:func:`record_multisine`, for tests that record their own data."""
    return record_multisine


def ppo_best_actor(run_dir, dataset, robot, cfg):
    """The rsl-rl actor a PPO run kept in ``best.pt`` (the networks :func:`wresdyn.ppo.trainer.train` builds, in eval
    mode) and a fresh :class:`~wresdyn.ppo.replay_env.ReplayEnv` set up as ``train`` sets up its own."""
    from wresdyn.ppo.trainer import runner_cfg
    from wresdyn.ppo.runner import Runner
    from wresdyn.ppo.replay_env import ReplayEnv
    from wresdyn.learn.residual import obs_stats
    from wresdyn.learn.runs import load_checkpoint

    trajs = dataset.split("train")
    mean, std = obs_stats(trajs)
    env = ReplayEnv(robot, trajs, dataset.rate_hz, cfg.env.num_worlds, cfg.env, cfg.residual, cfg.rewards,
                    seed=cfg.ppo.seed, obs_mean=mean, obs_std=std)
    actor = Runner(env, runner_cfg(cfg), log_dir=None).alg.get_policy()
    actor.load_state_dict(load_checkpoint(run_dir / "best.pt", keys=("actor", "meta"))["actor"])
    return actor.eval(), env


@pytest.fixture(scope="session")
def best_actor():
    """:func:`ppo_best_actor`, for the PPO tests."""
    return ppo_best_actor
