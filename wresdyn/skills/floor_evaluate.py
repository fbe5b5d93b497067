"""Deploy a skill on the floor and measure it as ASAP does: success, falls, joint and global body-position errors.

:func:`deploy_floor` plays every motion once from its start, one world each, with the policy's deterministic action,
and :func:`floor_metrics` reduces the rollouts (per motion, then the mean over motions):

- ``success``: the motion ran to its end with no fall and the base never more than ``max_base_error`` (0.5 m) from
  the reference's; ``falls``: motions that ended in a fall (base height or tilt past the task's limits);
- ``mpjpe``: mean |q − q_ref| over joints and policy steps of the true joint state [rad];
- ``g_mpjpe``: mean distance of every link's world position from the reference's (the reference base carrying the
  reference joints) [m];
- ``orientation_error``: mean angle between the base's orientation and the reference's [rad];
- ``foot_slip``: mean horizontal speed of the soles over the steps the reference keeps them planted [m/s];
- ``action_rate``: mean |Δ q_cmd| per policy step [rad].

A failed motion's errors count up to its failure (a failure never improves a mean); success and falls count it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..sim.kinematics import BodyPositions
from .floor_env import FAILURE_CAUSES, FloorTrackingEnv

__all__ = ["FloorDeployment", "deploy_floor", "floor_metrics", "FLOOR_METRICS"]

FLOOR_METRICS = ("success", "falls", "mpjpe", "g_mpjpe", "orientation_error", "foot_slip", "action_rate")


@dataclass
class FloorDeployment:
    """Rollouts of one policy on one floor plant, one per motion, at the policy rate; rows after a failure NaN."""

    q: np.ndarray
    """True joint positions [rad] (M, K + 1, n)."""
    base: np.ndarray
    """Base pose [x y z qx qy qz qw] (M, K + 1, 7)."""
    bodies: np.ndarray
    """World positions of every link [m] (M, K + 1, n_bodies, 3)."""
    q_ref: np.ndarray
    """Reference joints [rad] (M, K + 1, n)."""
    base_ref: np.ndarray
    """Reference base pose (M, K + 1, 7)."""
    bodies_ref: np.ndarray
    """Reference link positions [m] (M, K + 1, n_bodies, 3)."""
    planted: np.ndarray
    """Soles the reference plants, bool (M, K + 1, 2)."""
    feet: np.ndarray
    """Indices of the two foot bodies in ``bodies``."""
    cmd: np.ndarray
    """Commanded PD targets [rad] (M, K, n)."""
    failed_at: np.ndarray
    """Policy step of the failure, −1 if none (M,)."""
    fell: np.ndarray
    """Whether the failure was a fall (M,) bool."""
    cause: np.ndarray
    """Why each motion failed (M,): ``""`` if it did not, else one of :data:`~.floor_env.FAILURE_CAUSES`."""
    base_error_max: np.ndarray
    """Largest distance of the base from the reference's over the rollout [m] (M,)."""
    policy_dt: float
    names: list


def deploy_floor(policy, plant, motions, cfg) -> FloorDeployment:
    """Play ``motions`` on the floor ``plant`` (``n_worlds`` = number of motions) under ``policy`` (``None``: the
    reference played open loop) with the task ``cfg`` (:class:`~wresdyn.skills.floor_env.FloorTaskConfig`)."""

    if plant.n_worlds != len(motions):
        raise ValueError(f"{len(motions)} motions need as many worlds, the plant has {plant.n_worlds}")
    env = FloorTrackingEnv(plant, motions, cfg, random_start=False)
    k_len = env.ref_len.cpu().numpy()
    steps = int(k_len.max())
    m_n, n, nb = len(motions), plant.robot.n_dof, len(plant.robot.body_names)
    q = np.full((m_n, steps + 1, n), np.nan)
    base = np.full((m_n, steps + 1, 7), np.nan)
    bodies = np.full((m_n, steps + 1, nb, 3), np.nan)
    cmd = np.full((m_n, steps, n), np.nan)
    q[:, 0], base[:, 0], bodies[:, 0] = env.true_q.cpu(), env.base_pose.cpu(), env.bodies.cpu()
    failed_at, fell = np.full(m_n, -1), np.zeros(m_n, dtype=bool)
    cause, base_error_max = np.full(m_n, "", dtype=object), np.zeros(m_n)
    alive = np.ones(m_n, dtype=bool)
    obs = env.get_observations()["policy"]
    with torch.no_grad():
        for k in range(steps):
            act = torch.zeros(m_n, n) if policy is None else policy(obs.cpu())
            obs_td, _, dones, extras = env.step(act.to(env.device))
            obs = obs_td["policy"]
            done = dones.cpu().numpy().astype(bool)
            timeout = extras["time_outs"].cpu().numpy().astype(bool)
            live = alive & (k < k_len)
            cmd[live, k] = env.cmd.cpu().numpy()[live]
            q[live, k + 1] = env.step_true_q.cpu().numpy()[live]
            base[live, k + 1] = env.step_base_pose.cpu().numpy()[live]
            bodies[live, k + 1] = env.step_bodies.cpu().numpy()[live]
            fail = live & done & ~timeout
            failed_at[fail] = k + 1
            fell[fail] = env.fell.cpu().numpy()[fail]
            code = env.failure_cause.cpu().numpy()
            cause[fail] = [FAILURE_CAUSES[c - 1] for c in code[fail]]
            base_error_max[live] = np.maximum(base_error_max[live], env.base_error.cpu().numpy()[live])
            alive &= ~(done & live)
    r = env.ref_data
    q_ref, base_ref = r["q"][:, :steps + 1].cpu().numpy(), r["base"][:, :steps + 1].cpu().numpy()
    fk = BodyPositions(plant.robot, m_n, "cpu")
    bodies_ref = np.stack([fk(torch.as_tensor(base_ref[:, k]), torch.as_tensor(q_ref[:, k])).numpy()
                           for k in range(steps + 1)], axis=1)
    return FloorDeployment(q, base, bodies, q_ref, base_ref, bodies_ref, r["planted"][:, :steps + 1].cpu().numpy(),
                           env.feet.cpu().numpy(), cmd, failed_at, fell, cause, base_error_max, env.policy_dt,
                           [m.name for m in motions])


def _angle(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    return 2.0 * np.arccos(np.clip(np.abs((qa * qb).sum(-1)), 0.0, 1.0))


def floor_metrics(dep: FloorDeployment) -> dict:
    """Per-motion and mean figures of a floor deployment (:data:`FLOOR_METRICS`); see the module docstring."""
    per = []
    for i, name in enumerate(dep.names):
        ok = np.isfinite(dep.q[i, 1:]).all(-1)
        q, qr = dep.q[i, 1:][ok], dep.q_ref[i, 1:][ok]
        b, br = dep.bodies[i, 1:][ok], dep.bodies_ref[i, 1:][ok]
        ang = _angle(dep.base[i, 1:, 3:][ok], dep.base_ref[i, 1:, 3:][ok])
        feet = dep.bodies[i][:, dep.feet, :2]  # (K + 1, 2, 2)
        speed = np.linalg.norm(np.diff(feet, axis=0), axis=-1) / dep.policy_dt  # (K, 2)
        planted = dep.planted[i, 1:] & dep.planted[i, :-1]
        use = planted & np.isfinite(speed)
        c = dep.cmd[i][np.isfinite(dep.cmd[i]).all(-1)]
        nan = float("nan")
        per.append({"motion": name, "success": bool(dep.failed_at[i] < 0), "fell": bool(dep.fell[i]),
                    "failed_at": int(dep.failed_at[i]), "cause": str(dep.cause[i]),
                    "base_error_max": float(dep.base_error_max[i]),
                    "mpjpe": float(np.abs(q - qr).mean()) if len(q) else nan,
                    "g_mpjpe": float(np.linalg.norm(b - br, axis=-1).mean()) if len(b) else nan,
                    "orientation_error": float(ang.mean()) if len(ang) else nan,
                    "foot_slip": float(speed[use].mean()) if use.any() else nan,
                    "action_rate": float(np.abs(np.diff(c, axis=0)).mean()) if len(c) > 1 else 0.0})
    keys = ("mpjpe", "g_mpjpe", "orientation_error", "foot_slip", "action_rate")
    mean = {k: float(np.nanmean([p[k] for p in per])) for k in keys if np.isfinite([p[k] for p in per]).any()}
    mean["success"] = float(np.mean([p["success"] for p in per]))
    mean["failures"] = int(sum(not p["success"] for p in per))
    mean["falls"] = int(sum(p["fell"] for p in per))
    mean["causes"] = {c: sum(p["cause"] == c for p in per) for c in FAILURE_CAUSES}
    return {"mean": mean, "motions": per}
