"""Deploy a skill on a plant and measure its tracking, as ASAP evaluates (MPJPE, body positions, success).

:func:`deploy_skill` plays every motion once from its start, one world each, with the policy's deterministic
action, and :func:`metrics` reduces the rollouts:

- ``mpjpe``: mean per-joint position error |q − q_ref| over joints and policy steps [rad];
- ``foot_error``: mean distance of each sole from the reference's (Pinocchio forward kinematics) [m];
- ``success``: the episode ran to the motion's end with no joint more than ``fail_error`` from its reference and
  no runaway (a failed episode's errors count up to the failure: a failure never improves the mean);
- ``action_rate``: mean |a_t − a_{t−1}| of the commanded PD targets [rad per policy step];
- ``torque_rate``: mean |τ_k − τ_{k−1}| of the drive torque at the physics step [N*m per step] (plants that report
  torque: the real robot).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..data.ik import FootIK
from .env import TrackingEnv

__all__ = ["Deployment", "deploy_skill", "metrics", "METRICS", "gap_closed"]

METRICS = ("mpjpe", "foot_error", "success", "action_rate", "torque_rate")


@dataclass
class Deployment:
    """Rollouts of one policy on one plant, one per motion, at the policy rate."""

    q: np.ndarray
    """True joint positions [rad] (M, K + 1, n); NaN after a failure."""
    q_ref: np.ndarray
    """Reference [rad] (M, K + 1, n)."""
    feet_ref: np.ndarray
    """Reference sole positions [m] (M, K + 1, n_feet, 3) (:attr:`~.motions.Motion.feet` at the policy rate)."""
    cmd: np.ndarray
    """Commanded PD targets [rad] (M, K, n)."""
    failed_at: np.ndarray
    """Policy step of the failure, −1 if none (M,)."""
    torque_rate: np.ndarray
    """Mean |Δτ| per motion [N*m per physics step] (M,), NaN where the plant reports no torque."""
    names: list


def deploy_skill(policy, plant, motions, cfg) -> Deployment:
    """Play ``motions`` on ``plant`` (``n_worlds`` = number of motions) under ``policy`` (``None``: the reference
    played open loop, zero action) with the task ``cfg`` (:class:`~wresdyn.skills.env.SkillConfig`)."""

    if plant.n_worlds != len(motions):
        raise ValueError(f"{len(motions)} motions need as many worlds, the plant has {plant.n_worlds}")
    env = TrackingEnv(plant, motions, cfg, random_start=False)
    k_len = env.ref_len.cpu().numpy()
    steps = int(k_len.max())
    m_n, n = len(motions), plant.robot.n_dof
    q = np.full((m_n, steps + 1, n), np.nan)
    cmd = np.full((m_n, steps, n), np.nan)
    q[:, 0] = env.ref_q[:, 0].cpu().numpy()  # every motion starts in its reference state
    failed_at = np.full(m_n, -1)
    alive = np.ones(m_n, dtype=bool)
    has_tau = getattr(plant, "tau", None) is not None
    tau_rate, tau_last = np.zeros(m_n), None
    obs = env.get_observations()["policy"]
    with torch.no_grad():
        for k in range(steps):
            act = torch.zeros(m_n, n) if policy is None else policy(obs.cpu()).to(env.device)
            obs_td, _, dones, extras = env.step(act)
            obs = obs_td["policy"]
            done = dones.cpu().numpy().astype(bool)
            timeout = extras["time_outs"].cpu().numpy().astype(bool)
            live = alive & (k < k_len)
            cmd[live, k] = env.cmd.cpu().numpy()[live]
            q[live, k + 1] = env.true_q.cpu().numpy()[live]
            fail = live & done & ~timeout
            failed_at[fail] = k + 1
            q[fail, k + 1] = np.nan
            if has_tau:
                tau = plant.tau
                seq = tau if tau_last is None else np.concatenate([tau_last[:, None], tau], axis=1)
                tau_rate[live] += np.abs(np.diff(seq, axis=1)).mean(axis=(1, 2))[live]
                tau_last = tau[:, -1]
            alive &= ~(done & live)
    tau_rate = tau_rate / np.maximum(k_len, 1) if has_tau else np.full(m_n, np.nan)
    q_ref = env.ref_q[:, :steps + 1].cpu().numpy()
    feet_ref = np.stack([np.concatenate([f, np.repeat(f[-1:], steps + 1 - len(f), 0)]) for f in
                         (m.feet[::cfg.decimation][:k + 1] for m, k in zip(motions, k_len))])
    return Deployment(q, q_ref, feet_ref, cmd, failed_at, tau_rate, [m.name for m in motions])


def metrics(dep: Deployment, robot, frames=None) -> dict:
    """Per-motion and mean figures of a deployment (:data:`METRICS`), NaN-free: a failed motion's errors are
    averaged up to its failure and it counts as a failure in ``success``."""

    ik = FootIK(robot) if frames is None else FootIK(robot, tuple(frames))
    per = []
    for i, name in enumerate(dep.names):
        ok = np.isfinite(dep.q[i, 1:]).all(-1)
        e = np.abs(dep.q[i, 1:][ok] - dep.q_ref[i, 1:][ok])
        feet = np.array([ik.forward(x)[0] for x in dep.q[i, 1:][ok]]) if ok.any() else np.zeros((0, 2, 3))
        ref_feet = dep.feet_ref[i, 1:][ok]
        c = dep.cmd[i][np.isfinite(dep.cmd[i]).all(-1)]
        per.append({"motion": name, "mpjpe": float(e.mean()) if e.size else float("nan"),
                    "foot_error": float(np.linalg.norm(feet - ref_feet, axis=-1).mean()) if feet.size else float("nan"),
                    "success": bool(dep.failed_at[i] < 0),
                    "failed_at": int(dep.failed_at[i]),
                    "action_rate": float(np.abs(np.diff(c, axis=0)).mean()) if len(c) > 1 else 0.0,
                    "torque_rate": float(dep.torque_rate[i])})
    mean = {k: float(np.nanmean([p[k] for p in per])) for k in ("mpjpe", "foot_error", "action_rate", "torque_rate")
            if np.isfinite([p[k] for p in per]).any()}
    mean["success"] = float(np.mean([p["success"] for p in per]))
    mean["failures"] = int(sum(not p["success"] for p in per))
    return {"mean": mean, "motions": per}


def gap_closed(a: float, b: float, d: float) -> float:
    """(a − b) / (a − d): the fraction of the nominal-to-oracle tracking gap that ``b`` closes (NaN if a = d)."""
    return float((a - b) / (a - d)) if a != d else float("nan")
