"""A deployed skill as the drift benchmark's motion (``benchmarks/adapt/adapt_drift_policy.py``) at tiny size: a policy
trained for one PPO iteration runs closed loop on the drifting real robot, its log holds every sample with the PD
target the policy wrote, the drift reaches the plant's MuJoCo model, and the online identifier consumes the stream."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from wresdyn.adapt.adapter import Adapter
from wresdyn.adapt.config import AdaptConfig
from wresdyn.data.real_robot import RealRobot
from wresdyn.sim.physics import PhysicalParams
from wresdyn.skills.env import SkillConfig, TrackingEnv
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.skill_config import SkillPPOConfig
from wresdyn.skills.skill_ppo import train_skill

BENCH = Path(__file__).resolve().parents[2] / "benchmarks" / "adapt"
RATE = 500.0
SECONDS = 3.0
"""Robot time of the run [s]: the drift timeline scaled to it ramps the leg friction from 0.375 to 1.5 s."""


def _load(name):
    spec = importlib.util.spec_from_file_location(name, BENCH / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def skill(humanoid, tmp_path_factory):
    task = SkillConfig()
    motions = make_motions(humanoid, {"train": 1}, duration=0.4, rate_hz=RATE, seed=3).split("train")
    env = TrackingEnv(SimPlant(humanoid, 4, RATE, task.decimation), motions, task)
    ppo = SkillPPOConfig(iterations=1, num_steps_per_env=4, hidden_dims=(16,), num_mini_batches=1,
                         torch_threads=1)
    out = tmp_path_factory.mktemp("skill") / "tiny"
    train_skill(env, ppo, out, log=lambda *_: None)
    return out


def test_policy_stream_is_the_robot_log_and_the_adapter_consumes_it(humanoid, shipped_mismatch, skill):
    bench, pol = _load("adapt_drift"), _load("adapt_drift_policy")
    real = RealRobot(humanoid, shipped_mismatch, RATE)
    drift = bench.Drift(real, humanoid, bench.phases(SECONDS), RATE)
    friction0 = real.model.dof_frictionloss.copy()
    called = []

    def hook(k, m):
        called.append(k)
        drift(k, m)

    samples = int(SECONDS * RATE) + 1
    ref_q, ref_feet, names = bench.skill_reference(humanoid, samples, RATE, "heldout", 0)
    np.testing.assert_array_equal(ref_q, bench.skill_commands(humanoid, SECONDS + 1, RATE, "heldout", 0)[:samples])
    first = bench.skill_motions(humanoid, RATE, "heldout", 0)[:2]  # each motion, then a 0.2 s blend to the next
    n0 = len(first[0].q)
    assert (names[:n0] == first[0].name).all() and (names[n0:n0 + 100] == "blend").all()
    second = ref_q[n0 + 100:n0 + 100 + len(first[1].q)]  # cut at the run's end
    np.testing.assert_array_equal(second, first[1].q[:len(second)])
    assert len(second) > 100 and (names[n0 + 100:n0 + 100 + len(second)] == first[1].name).all()
    run = pol.policy_stream(skill, real, hook, ref_q, ref_feet, RATE, seed=0)
    task, n = SkillConfig(), humanoid.n_dof
    assert run.q.shape == run.qd.shape == run.q_cmd.shape == (samples - 1, n)
    assert np.isfinite(run.q).all() and np.isfinite(run.qd).all()
    # the hook ran before every policy step, at its first sample
    assert called == list(range(0, samples - 1, task.decimation))
    # the command is the policy's PD target, held for the policy period, within the action's reach of the reference
    blocks = run.q_cmd.reshape(-1, task.decimation, n)
    assert (blocks == blocks[:, :1]).all()
    reach = task.action_scale * task.action_clip
    assert np.abs(blocks[:, 0] - ref_q[task.decimation::task.decimation]).max() <= reach + 1e-6
    # the robot follows it: sensed position near the command, the policy's tracking error small and finite
    assert np.abs(run.q - run.q_cmd).mean() < 0.05, np.abs(run.q - run.q_cmd).mean()
    assert run.tracking.shape == run.worst.shape == (samples // task.decimation,) and run.tracking.max() < 0.2
    np.testing.assert_array_equal(run.worst, run.joint_error.max(-1))
    np.testing.assert_allclose(run.tracking, run.joint_error.mean(-1))
    assert run.fail_error == task.fail_error
    # the drift reached the plant's model: the leg friction doubled by the end of the ramp
    np.testing.assert_allclose(real.model.dof_frictionloss[:12], 2.0 * friction0[:12])
    cfg = AdaptConfig(window=1.2, holdout=0.3, update_every=0.5, iterations=2, windows=4, horizon=16,
                      one_step_every=10)
    calib = PhysicalParams.load(BENCH.parent / "results" / "grey_box" / "soft_friction" / "physics.json", humanoid)
    adapter = Adapter(humanoid, calib, RATE, cfg)
    t = np.arange(len(run.q)) / RATE
    updates = [u for s in range(0, len(t), 50) for u in adapter.push(t[s:s + 50], run.q[s:s + 50],
                                                                     run.qd[s:s + 50], run.q_cmd[s:s + 50])]
    assert len(updates) >= 3
    assert all(np.isfinite(u.open_loop) and u.open_loop < 0.05 for u in updates), [u.open_loop for u in updates]
