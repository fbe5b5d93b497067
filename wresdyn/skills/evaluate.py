"""Deploy a skill on a plant and measure its tracking as ASAP evaluates, on the stand or on the floor.

:func:`deploy` plays every motion once from its start, one world each, with the policy's deterministic action, and
:func:`metrics` reduces the rollouts (per motion, then the mean over motions; :data:`METRICS` by task). Both tasks:

- ``mpjpe``: mean per-joint position error |q − q_ref| of the true joint state over joints and policy steps [rad];
- ``success``: the episode ran to the motion's end without failing (the task's rule: on the stand no joint more than
  ``fail_error`` from its reference and no runaway; on the floor no fall, no runaway and the base never more than
  ``max_base_error`` (0.5 m) from the reference's);
- ``action_rate``: mean |a_t − a_{t−1}| of the commanded PD targets [rad per policy step].

On the stand also:

- ``foot_error``: mean distance of each sole from the reference's (Pinocchio forward kinematics) [m];
- ``torque_rate``: mean |τ_k − τ_{k−1}| of the drive torque at the physics step [N*m per step] (plants that report
  torque: the real robot).

On the floor also:

- ``falls``, ``drifts``, ``diverged``: how many motions failed by each kind of failure (:data:`~.env.FAILURE_CAUSES`).
  A fall is the base dropping ``fall_height`` below its reference or tilting past ``fall_tilt``. A world whose base
  drifts more than ``max_base_error`` from the reference has failed there, but it plays on to its motion's end: a
  fall before then makes the failure a fall (a topple that drifts first is a fall), none leaves it a drift; a
  runaway (the simulation diverged) is its own class (a drifted world that runs away later stays a drift);
- ``g_mpjpe``: mean distance of every link's world position from the reference's (the reference base carrying the
  reference joints) [m];
- ``orientation_error``: mean angle between the base's orientation and the reference's [rad];
- ``foot_slip``: mean horizontal speed of the soles over the steps the reference keeps them planted [m/s].

A failed motion's errors count up to its failure (a failure never improves a mean), the steps a drifted world plays
on included in none of them; success and the failure counts count it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from ..data.ik import FootIK
from ..sim.kinematics import BodyPositions
from .env import FAILURE_CAUSES, FALLS, TrackingEnv
from .reference import plant_dt

__all__ = ["Deployment", "deploy", "metrics", "METRICS", "GAP_MARGIN", "gap_closed", "gaps_or_why_not"]

METRICS = {"stand": ("mpjpe", "foot_error", "success", "action_rate", "torque_rate"),
           "floor": ("success", "falls", "drifts", "diverged", "mpjpe", "g_mpjpe", "orientation_error", "foot_slip",
                     "action_rate")}
"""What :func:`metrics` reports, by task."""


@dataclass
class Deployment:
    """Rollouts of one policy on one plant, one per motion, at the policy rate. The floor's fields are ``None`` on the
    stand, the stand's on the floor."""

    q: np.ndarray
    """True joint positions [rad] (M, K + 1, n); NaN after a failure (on the stand from the failed step)."""
    q_ref: np.ndarray
    """Reference [rad] (M, K + 1, n)."""
    cmd: np.ndarray
    """Commanded PD targets [rad] (M, K, n)."""
    failed_at: np.ndarray
    """Policy step of the failure, −1 if none (M,)."""
    names: list
    policy_dt: float
    """Policy period [s]."""
    floating: bool = False
    """The rollouts are on the floor."""
    feet_ref: np.ndarray | None = None
    """Stand: reference sole positions [m] (M, K + 1, n_feet, 3) (:attr:`~.motions.Motion.feet` at the policy rate)."""
    torque_rate: np.ndarray | None = None
    """Stand: mean |Δτ| per motion [N*m per physics step] (M,), NaN where the plant reports no torque."""
    base: np.ndarray | None = None
    """Floor: base pose [x y z qx qy qz qw] (M, K + 1, 7)."""
    bodies: np.ndarray | None = None
    """Floor: world positions of every link [m] (M, K + 1, n_bodies, 3)."""
    base_ref: np.ndarray | None = None
    """Floor: reference base pose (M, K + 1, 7)."""
    bodies_ref: np.ndarray | None = None
    """Floor: reference link positions [m] (M, K + 1, n_bodies, 3)."""
    planted: np.ndarray | None = None
    """Floor: soles the reference plants, bool (M, K + 1, 2)."""
    feet: np.ndarray | None = None
    """Floor: indices of the two foot bodies in ``bodies``."""
    fell: np.ndarray | None = None
    """Floor: whether the failure was a fall (M,) bool, seen at the failure or after a drift."""
    cause: np.ndarray | None = None
    """Floor: why each motion failed (M,): ``""`` if it did not, else one of :data:`~.env.FAILURE_CAUSES` (a fall
    after a drift is the fall's cause)."""
    fell_at: np.ndarray | None = None
    """Floor: policy step of the fall, −1 if none (M,); later than ``failed_at`` where the base drifted first."""
    base_error_max: np.ndarray | None = None
    """Floor: largest distance of the base from the reference's over the rollout [m] (M,)."""


def deploy(policy, plant, motions, cfg) -> Deployment:
    """Play ``motions`` on ``plant`` (``num_worlds`` = number of motions) under ``policy`` (``None``: the reference
    played open loop, zero action) with the task ``cfg`` (:class:`~wresdyn.skills.skill_config.SkillTaskConfig`)."""

    if plant.num_worlds != len(motions):
        raise ValueError(f"{len(motions)} motions need as many worlds, the plant has {plant.num_worlds}")
    env = TrackingEnv(plant, motions, cfg, random_start=False, drift_ends=False)
    floor = env.floating
    k_len = env.ref_len.cpu().numpy()
    steps = int(k_len.max())
    m_n, n = len(motions), plant.robot.n_dof
    q = np.full((m_n, steps + 1, n), np.nan)
    cmd = np.full((m_n, steps, n), np.nan)
    failed_at = np.full(m_n, -1)
    alive = np.ones(m_n, dtype=bool)
    if floor:
        nb = len(plant.robot.body_names)
        base, bodies = np.full((m_n, steps + 1, 7), np.nan), np.full((m_n, steps + 1, nb, 3), np.nan)
        q[:, 0], base[:, 0], bodies[:, 0] = env.true_q.cpu(), env.base_pose.cpu(), env.bodies.cpu()
        fell, cause, base_error_max = np.zeros(m_n, dtype=bool), np.full(m_n, "", dtype=object), np.zeros(m_n)
        fell_at = np.full(m_n, -1)
    else:
        q[:, 0] = env.ref_q[:, 0].cpu().numpy()  # every motion starts in its reference state
    has_tau = not floor and getattr(plant, "tau", None) is not None
    tau_rate, tau_last = np.zeros(m_n), None
    obs = env.get_observations()["policy"]
    with torch.no_grad():
        for k in range(steps):
            act = torch.zeros(m_n, n) if policy is None else policy(obs.cpu())
            obs_td, _, dones, extras = env.step(act.to(env.device))
            obs = obs_td["policy"]
            done = dones.cpu().numpy().astype(bool)
            timeout = extras["time_outs"].cpu().numpy().astype(bool)
            live = alive & (k < k_len)
            ended = live & done & ~timeout  # a fall or a runaway (on the floor a drift plays on)
            # what the metrics read: up to and including the step of the failure
            rec = live & (failed_at < 0) if floor else live
            cmd[rec, k] = env.cmd.cpu().numpy()[rec]
            q[rec, k + 1] = env.step_true_q.cpu().numpy()[rec]
            if floor:
                base[rec, k + 1] = env.step_base_pose.cpu().numpy()[rec]
                bodies[rec, k + 1] = env.step_bodies.cpu().numpy()[rec]
                base_error_max[rec] = np.maximum(base_error_max[rec], env.base_error.cpu().numpy()[rec])
                code = env.failure_cause.cpu().numpy()
                fall = ended & np.isin(code, [1 + FAILURE_CAUSES.index(c) for c in FALLS])
                drift = rec & env.drifted.cpu().numpy() & ~fall
                first = (fall | drift | ended) & (failed_at < 0)
                failed_at[first] = k + 1
                # a fall outranks the drift before it; otherwise the first failure names the cause
                cause[drift & first] = "drifted"
                cause[ended & first & ~fall & ~drift] = "diverged"
                cause[fall] = [FAILURE_CAUSES[c - 1] for c in code[fall]]
                fell[fall], fell_at[fall] = True, k + 1
            else:
                failed_at[ended] = k + 1
                q[ended, k + 1] = np.nan
            if has_tau:
                tau = plant.tau
                seq = tau if tau_last is None else np.concatenate([tau_last[:, None], tau], axis=1)
                tau_rate[live] += np.abs(np.diff(seq, axis=1)).mean(axis=(1, 2))[live]
                tau_last = tau[:, -1]
            alive &= ~(done & live)
    q_ref = env.ref_q[:, :steps + 1].cpu().numpy()
    names = [m.name for m in motions]
    if not floor:
        tau_rate = tau_rate / np.maximum(k_len, 1) if has_tau else np.full(m_n, np.nan)
        feet_ref = np.stack([np.concatenate([f, np.repeat(f[-1:], steps + 1 - len(f), 0)]) for f in
                             (m.feet[::cfg.decimation][:k + 1] for m, k in zip(motions, k_len))])
        return Deployment(q, q_ref, cmd, failed_at, names, cfg.decimation * plant_dt(plant), feet_ref=feet_ref,
                          torque_rate=tau_rate)
    r = env.ref_data
    base_ref = r["base"][:, :steps + 1].cpu().numpy()
    fk = BodyPositions(plant.robot, m_n, "cpu")
    bodies_ref = np.stack([fk(torch.as_tensor(base_ref[:, k]), torch.as_tensor(q_ref[:, k])).numpy()
                           for k in range(steps + 1)], axis=1)
    return Deployment(q, q_ref, cmd, failed_at, names, env.policy_dt, floating=True, base=base, bodies=bodies,
                      base_ref=base_ref, bodies_ref=bodies_ref, planted=r["planted"][:, :steps + 1].cpu().numpy(),
                      feet=env.feet.cpu().numpy(), fell=fell, cause=cause, base_error_max=base_error_max,
                      fell_at=fell_at)


def _angle(qa: np.ndarray, qb: np.ndarray) -> np.ndarray:
    return 2.0 * np.arccos(np.clip(np.abs((qa * qb).sum(-1)), 0.0, 1.0))


def metrics(dep: Deployment, robot=None, frames=None) -> dict:
    """Per-motion and mean figures of a deployment (:data:`METRICS`), NaN-free; see the module docstring. On the
    stand ``robot`` (with sole ``frames``, default the IK's) gives the soles' forward kinematics."""
    return _floor_metrics(dep) if dep.floating else _stand_metrics(dep, robot, frames)


def _stand_metrics(dep: Deployment, robot, frames) -> dict:
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


def _floor_metrics(dep: Deployment) -> dict:
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
                    "failed_at": int(dep.failed_at[i]), "cause": str(dep.cause[i]), "fell_at": int(dep.fell_at[i]),
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
    mean["causes"] = {c: int(sum(p["cause"] == c for p in per)) for c in FAILURE_CAUSES}
    mean["falls"] = int(sum(p["fell"] for p in per))
    mean["drifts"], mean["diverged"] = mean["causes"]["drifted"], mean["causes"]["diverged"]
    return {"mean": mean, "motions": per}


def gap_closed(a: float, b: float, d: float) -> float:
    """(a − b) / (a − d): the fraction of the nominal-to-oracle tracking gap that ``b`` closes (NaN if a = d)."""
    return float((a - b) / (a - d)) if a != d else float("nan")


GAP_MARGIN = 0.05
"""The oracle's error must be below (a)'s by this fraction of (a)'s for a gap ratio to be quoted: a ratio over a
smaller gap divides a few tenths of a mrad and swings by hundreds of percent between runs."""
_SHOWN = {"mpjpe": ("MPJPE", 1e3, "mrad"), "g_mpjpe": ("g-MPJPE", 1e3, "mm")}
"""How a metric is named and scaled in a reason."""


def gaps_or_why_not(split: dict, metric: str = "mpjpe") -> tuple[dict, str]:
    """The gaps closed by (b) and (c) on ``metric`` of one split's deployments (``{policy: metrics(...)}``), or none
    and the reason, so that no ratio is quoted whose oracle does not beat (a): ``({}, why)`` when no policy succeeded
    on any motion (``why`` = ``"no policy succeeded"``), when (a) or the oracle (d) is missing, or when (d) does not
    beat (a) (a ``metric`` no lower, or lower by less than :data:`GAP_MARGIN`, or a lower success: a policy that fails
    early also stops its errors early);
    else ``({policy: fraction}, "")``."""
    runs = {k: v["mean"] for k, v in split.items() if k != "reference"}
    if not runs or all(m["success"] == 0.0 for m in runs.values()):
        return {}, "no policy succeeded"
    if "a_nominal" not in runs or "d_oracle" not in runs:
        return {}, "needs (a) and the oracle (d)"
    a, d = runs["a_nominal"], runs["d_oracle"]
    ea, ed = a.get(metric, float("nan")), d.get(metric, float("nan"))
    name, scale, unit = _SHOWN.get(metric, (metric, 1.0, ""))
    if not ed < ea:
        return {}, f"the oracle (d) does not beat (a) on {name} ({scale * ed:.1f} against {scale * ea:.1f} {unit})"
    if not ed < (1.0 - GAP_MARGIN) * ea:
        return {}, (f"the oracle (d) beats (a) on {name} by less than {100 * GAP_MARGIN:.0f} % ({scale * ed:.1f} "
                    f"against {scale * ea:.1f} {unit}): a ratio of so small a gap is noise")
    if d["success"] < a["success"]:
        return {}, (f"the oracle (d) does not beat (a): it succeeds less ({100 * d['success']:.0f} % against "
                    f"{100 * a['success']:.0f} %)")
    return {k: gap_closed(ea, runs[k].get(metric, float("nan")), ed) for k in ("b_calibrated", "c_delta_action")
            if k in runs}, ""
