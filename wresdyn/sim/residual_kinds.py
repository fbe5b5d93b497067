"""How a residual enters the simulation: its kinds, its authority, what it observes, where it is applied.

Two kinds (the residual learners, :mod:`wresdyn.learn`, produce either):

* ``"torque"`` (the paper, eq. 1): M(q)q̈ + C(q,q̇)q̇ + G(q) + f(q,q̇,q̈) = τ_pd + τ_res, τ_res written to
  Newton's ``control.joint_f`` next to the PD drive.
* ``"delta_action"`` (ASAP): the residual shifts the PD target, q_target = q_cmd + Δq.

With Δ_max = fraction · effort_limit / kp the two kinds have the same authority: kp · Δ_max = τ_res max.
The residual observes the simulated joint state and the command, [q, q̇, q̈, q_cmd] (paper Sec. II-B).
"""

from __future__ import annotations

import numpy as np

from ..choices import ResidualKind, check_choice, choices

__all__ = ["KINDS", "residual_scale", "observation", "apply_residual"]

KINDS = choices(ResidualKind)
"""Residual kinds: joint torque added to τ_pd (paper) or offset added to the PD target (ASAP)."""


def residual_scale(robot, kind: str, fraction: float) -> np.ndarray:
    """Largest residual per joint, fraction · effort: [N*m] (torque) or [rad] (delta action), shape (n_dof,)."""
    check_choice(kind, ResidualKind, "kind")
    effort = np.asarray(robot.effort, dtype=np.float64)
    if not np.isfinite(effort).all():
        bad = [n for n, e in zip(robot.joint_names, effort) if not np.isfinite(e)]
        raise ValueError(f"{robot.source}: residual scale needs an effort limit on every joint; missing on {bad[:4]}")
    torque = fraction * effort
    return torque if kind == "torque" else torque / np.asarray(robot.kp, dtype=np.float64)


def observation(q, qd, qdd, q_cmd):
    """Raw observation [q, q̇, q̈, q_cmd] ([rad], [rad/s], [rad/s²], [rad]), torch tensors (N, n) each -> (N, 4n)."""
    import torch

    return torch.cat([q, qd, qdd, q_cmd], dim=-1)


def apply_residual(target, residual, kind: str):
    """PD target [rad] and joint torque [N*m] of one step, (N, n) each, with ``residual`` of ``kind`` applied.

    ``residual`` may be ``None`` (PD only). Returns ``(target, tau)``; ``tau`` is ``None`` where no torque
    is added, so the caller can skip writing it.
    """
    if residual is None:
        return target, None
    if kind == "torque":
        return target, residual
    check_choice(kind, ResidualKind, "kind")
    return target + residual, None
