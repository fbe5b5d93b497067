"""Rewards for residual-dynamics learning: Table I of the paper, one function per term.

Every term maps batched tensors of shape (N, n_dof) to one value per world, shape (N,), unweighted;
:func:`reward_terms` multiplies each by its weight from :class:`RewardConfig`, so the table lives in
one place. Mimic terms use the kernel φ(x) = exp(−|x|²/σ) with |x|² summed over joints.

Joints a dataset excludes from fitting (:meth:`wresdyn.data.dataset.Dataset.fit_weights`: 1 fitted, 0 excluded)
are left out of the terms that compare with the recording (position and velocity mimic, position bonus) by the
optional per-joint ``weights`` (n,): |x|² becomes Σ_j w_j x_j² and the bonus a w-weighted mean over joints. The
regularisers (torque, velocity, acceleration, action rate and acceleration) keep every joint: a residual on an
excluded joint is still penalised, never rewarded.

Table I (defaults below):

=========================  =========  ==========================================
Joint position mimic         5.0      φ(q − q_r)
Joint velocity mimic         3.0      φ(q̇ − q̇_r)
Joint position bonus        10.0      1{|q − q_r| < 1e-3}
Joint torque               −0.5e-5    |τ|²
Joint velocity             −0.5e-3    |q̇|²
Joint acceleration         −0.5e-6    |q̈|²
Action rate                −0.5e-4    |a_t − a_{t−1}|²
Action acceleration        −0.5e-6    |a_t − 2a_{t−1} + a_{t−2}|²
=========================  =========  ==========================================
"""

from __future__ import annotations

import torch

from .replay_env_config import RewardConfig

__all__ = [
    "RewardConfig",
    "TERMS",
    "kernel",
    "joint_pos_mimic",
    "joint_vel_mimic",
    "joint_pos_bonus",
    "joint_torque",
    "joint_vel",
    "joint_acc",
    "action_rate",
    "action_acc",
    "reward_terms",
]


TERMS = ("joint_pos_mimic", "joint_vel_mimic", "joint_pos_bonus", "joint_torque", "joint_vel", "joint_acc",
         "action_rate", "action_acc")
"""Reward term names, in Table I order; each is a function here and a weight in :class:`RewardConfig`."""


def kernel(x: torch.Tensor, sigma: float, weights: torch.Tensor | None = None) -> torch.Tensor:
    """φ(x) = exp(−|x|²/σ), |x|² summed over the last axis, each joint's x_j² times ``weights[j]`` when given
    (n,). (N, n) -> (N,)."""
    sq = x.square()
    return torch.exp(-(sq if weights is None else sq * weights).sum(-1) / sigma)


def joint_pos_mimic(q: torch.Tensor, q_r: torch.Tensor, sigma: float,
                    weights: torch.Tensor | None = None) -> torch.Tensor:
    """φ(q − q_r): simulated vs recorded joint positions [rad], per-joint ``weights`` (n,) as in :func:`kernel`.
    (N, n) -> (N,)."""
    return kernel(q - q_r, sigma, weights)


def joint_vel_mimic(qd: torch.Tensor, qd_r: torch.Tensor, sigma: float,
                    weights: torch.Tensor | None = None) -> torch.Tensor:
    """φ(q̇ − q̇_r): simulated vs recorded joint velocities [rad/s], per-joint ``weights`` (n,) as in :func:`kernel`.
    (N, n) -> (N,)."""
    return kernel(qd - qd_r, sigma, weights)


def joint_pos_bonus(q: torch.Tensor, q_r: torch.Tensor, tol: float,
                    weights: torch.Tensor | None = None) -> torch.Tensor:
    """1{|q − q_r| < tol}, read per joint and averaged over joints (a ``weights``-weighted mean when given, (n,)),
    in [0, 1]. (N, n) -> (N,).

    Read on the whole-robot norm, the indicator almost never fires with 21 joints and gives no signal;
    per joint it counts the joints already matched, and equals the table's indicator for one joint.
    """
    hit = ((q - q_r).abs() < tol).float()
    if weights is None:
        return hit.mean(-1)
    return (hit * weights).sum(-1) / weights.sum()


def joint_torque(tau: torch.Tensor) -> torch.Tensor:
    """|τ|², total joint torque [N*m]. (N, n) -> (N,)."""
    return tau.square().sum(-1)


def joint_vel(qd: torch.Tensor) -> torch.Tensor:
    """|q̇|² [rad/s]. (N, n) -> (N,)."""
    return qd.square().sum(-1)


def joint_acc(qdd: torch.Tensor) -> torch.Tensor:
    """|q̈|² [rad/s²]. (N, n) -> (N,)."""
    return qdd.square().sum(-1)


def action_rate(a: torch.Tensor, a_prev: torch.Tensor) -> torch.Tensor:
    """|a_t − a_{t−1}|² on normalised actions. (N, n) -> (N,)."""
    return (a - a_prev).square().sum(-1)


def action_acc(a: torch.Tensor, a_prev: torch.Tensor, a_prev2: torch.Tensor) -> torch.Tensor:
    """|a_t − 2a_{t−1} + a_{t−2}|² on normalised actions. (N, n) -> (N,)."""
    return (a - 2.0 * a_prev + a_prev2).square().sum(-1)


def reward_terms(
    cfg: RewardConfig,
    q: torch.Tensor,
    qd: torch.Tensor,
    qdd: torch.Tensor,
    q_r: torch.Tensor,
    qd_r: torch.Tensor,
    tau: torch.Tensor,
    a: torch.Tensor,
    a_prev: torch.Tensor,
    a_prev2: torch.Tensor,
    weights: torch.Tensor | None = None,
) -> dict[str, torch.Tensor]:
    """All weighted terms, name -> (N,); the step reward is their sum.

    Args:
        cfg: Weights and widths.
        q, qd, qdd: Simulated joint positions [rad], velocities [rad/s], accelerations [rad/s²], (N, n).
        q_r, qd_r: Recorded joint positions and velocities at the same time, (N, n).
        tau: Total joint torque applied during the step [N*m], (N, n).
        a, a_prev, a_prev2: Normalised actions at t, t−1, t−2, (N, n).
        weights: Per-joint weights (n,) of the mimic and bonus terms (``Dataset.fit_weights()``: 0 for a joint
            excluded from fitting); ``None``: every joint counts (Table I as written).
    """
    return {
        "joint_pos_mimic": cfg.joint_pos_mimic * joint_pos_mimic(q, q_r, cfg.sigma_q, weights),
        "joint_vel_mimic": cfg.joint_vel_mimic * joint_vel_mimic(qd, qd_r, cfg.sigma_qd, weights),
        "joint_pos_bonus": cfg.joint_pos_bonus * joint_pos_bonus(q, q_r, cfg.bonus_tol, weights),
        "joint_torque": cfg.joint_torque * joint_torque(tau),
        "joint_vel": cfg.joint_vel * joint_vel(qd),
        "joint_acc": cfg.joint_acc * joint_acc(qdd),
        "action_rate": cfg.action_rate * action_rate(a, a_prev),
        "action_acc": cfg.action_acc * action_acc(a, a_prev, a_prev2),
    }
