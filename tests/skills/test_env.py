"""The one skills pipeline over both task configurations (stand and floor): the motion registry, the environment's
observations, rewards and world count, at tiny sizes on the real code paths."""

from __future__ import annotations

import pytest
import torch

from wresdyn.skills.env import IMU_TERMS, OBS_TERMS, TrackingEnv
from wresdyn.skills.motions import TASK_FAMILIES, make_motions
from wresdyn.skills.plants import SimPlant
from wresdyn.skills.skill_config import SkillTaskConfig

from skill_runs import RATE

DURATION = {"stand": 0.4, "floor": 1.0}
"""Motion lengths [s]: as short as each task's motions still move."""


@pytest.fixture(scope="module", params=["stand", "floor"])
def task(request, humanoid, floating):
    """A task configuration, the robot it acts on and its motions (one per family and split)."""
    name = request.param
    cfg = getattr(SkillTaskConfig, name)(decimation=5)
    motions = make_motions(humanoid, {"train": 1, "heldout": 1}, duration=DURATION[name], rate_hz=RATE, seed=3,
                           floating=floating if cfg.floating else None, screen=False)  # 1 s carries no transfer
    return cfg, floating if cfg.floating else humanoid, motions


def test_each_task_draws_its_registered_families(task):
    cfg, _, motions = task
    fam = TASK_FAMILIES[cfg.name]
    assert [m.family for m in motions["train"]] == list(fam.train)
    assert [m.family for m in motions["heldout"]] == list(fam.train + fam.held_out)
    # a floor motion carries its base and planted soles; a stand motion has none
    assert all((m.base is not None) == cfg.floating and (m.planted is not None) == cfg.floating
               for m in motions["heldout"])


def test_one_environment_plays_either_task(task):
    """A zero action commands the reference; the policy sees the joint terms (and on the floor the IMU), the critic
    on the floor its privileged terms; the rewards are the task's terms; the world count is the plant's."""
    cfg, robot, motions = task
    n = robot.n_dof
    plant = SimPlant(robot, 2, RATE, 5, ground=cfg.floating)
    env = TrackingEnv(plant, motions["train"][:2], cfg, random_start=False)
    assert env.num_envs == plant.num_worlds == 2
    obs = env.get_observations()
    assert obs["policy"].shape == (2, len(OBS_TERMS) * n + (3 * len(IMU_TERMS) if cfg.floating else 0))
    assert ("critic" in obs.keys()) == cfg.floating and env.critic_groups == (("policy", "critic") if cfg.floating
                                                                               else ("policy",))
    _, cmd = env.command(torch.zeros(2, n))
    torch.testing.assert_close(cmd, env.ref(1))
    _, reward, done, extras = env.step(torch.zeros(2, n))
    assert torch.isfinite(reward).all() and not done.any()
    assert [k for k in extras["log"] if k.startswith("Reward/")] == [f"Reward/{t}" for t in cfg.reward_terms]
    assert env.step_true_q.shape == (2, n)
