"""The real robot in mujoco_warp (:class:`~wresdyn.skills.real_warp.RealWarpPlant`) against the MuJoCo C one
(:class:`~wresdyn.skills.plants.RealPlant`): the same held-out motion played open loop on both, noise off, on the
floor and on the stand; its sensors; the training environment on it; the deploy configs' choice of the oracle's
plant. mujoco_warp runs here on Warp's CPU device (the benchmark's on a GPU)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from wresdyn.errors import WresdynError
from wresdyn.experiments.deploy_config import DeployConfig, FloorDeployConfig
from wresdyn.skills.env import TrackingEnv
from wresdyn.skills.motions import make_motions
from wresdyn.skills.plants import RealPlant
from wresdyn.skills.real_warp import RealWarpPlant
from wresdyn.skills.skill_config import SkillTaskConfig

import skill_runs

RATE = skill_runs.RATE
DEC = 5
"""Recording periods per policy step (10 physics substeps of the real robot's 1 kHz)."""


@pytest.fixture(scope="module")
def quiet_floor(floating, shipped_mismatch):
    return skill_runs.quiet_real(floating, shipped_mismatch)


@pytest.fixture(scope="module")
def kick(humanoid, floating):
    """A held-out kick (a foot lifts and lands: contact made and broken), 0.6 s."""
    return make_motions(humanoid, {"heldout": 1}, duration=0.6, rate_hz=RATE, seed=3, floating=floating,
                        families=("kick",), held_out=())["heldout"]


def _play(plants, motions, floor: bool) -> tuple[np.ndarray, np.ndarray]:
    """Play each motion's reference open loop on every plant from its first sample; the largest joint difference
    [rad] and base position difference [m] between the first two plants after each policy step (K, M)."""
    m_n = len(motions)
    ids, q0 = torch.arange(m_n), torch.as_tensor(np.stack([m.q[0] for m in motions]))
    for p in plants:
        if floor:
            base = torch.as_tensor(np.stack([m.base[0] for m in motions]))
            p.reset_full(ids, base, torch.zeros(m_n, 6), q0, 0 * q0)
        else:
            p.reset(ids, q0, 0 * q0)
    dq, db = [], []
    for k in range(min(len(m.q) for m in motions) // DEC - 1):
        cmd = torch.as_tensor(np.stack([m.q[DEC * (k + 1)] for m in motions]))
        (qa, _, bad_a), (qb, _, bad_b) = (p.step(cmd) for p in plants)
        assert not bad_a.any() and not bad_b.any()
        dq.append((qa.cpu() - qb.cpu()).abs().max(-1).values.numpy())
        if floor:
            db.append((plants[0].base_pose.cpu() - plants[1].base_pose.cpu())[:, :3].abs().max(-1).values.numpy())
    return np.array(dq), np.array(db)


def test_on_the_floor_it_follows_the_mujoco_c_real_robot(quiet_floor, kick):
    """A held-out kick, noise off: the same model, delay line, torque limits and floor in float32. Measured over the
    0.6 s: joints 6e-5 rad, base 3e-5 m apart (float32 round-off, largest at the first step where the stiction and
    contact solve from a cold start); over 4 s of the five held-out floor motions, falls included, 2.6e-3 rad."""
    warp, mjc = RealWarpPlant(quiet_floor, 2, DEC, device="cpu"), RealPlant(quiet_floor, 2, DEC)
    dq, db = _play([warp, mjc], kick * 2, floor=True)
    assert dq.max() < 3e-4 and db.max() < 2e-4
    np.testing.assert_allclose(warp.base_twist.numpy(), mjc.base_twist.numpy(), atol=2e-3)
    np.testing.assert_allclose(warp.q_true.numpy(), mjc.q_true, atol=3e-4)
    # the base moved: a plant that ignored the commands or the floor would be centimetres off
    assert (np.abs(warp.base_pose[:, :3].numpy() - kick[0].base[0, :3]).max()) > 1e-3
