"""Parametric baseline: classical system identification of per-joint actuator and friction parameters.

Instead of a network, the correction is the physical model of what usually differs between a simulator and
a robot (as fitted by ``mujoco.sysid`` or PACE), per joint i:

    τ_res,i = (s_p,i − 1)·kp_i·(q_cmd,i − q_i) − (s_d,i − 1)·kd_i·q̇_i      PD gain error (exact for explicit PD)
              − b_i·q̇_i                                                    extra viscous damping
              − μ_i·tanh(q̇_i / v_s)                                        smoothed Coulomb friction
              − Δa_i·q̈_i                                                   extra armature (q̈ of the previous step)

with b, μ, Δa ≥ 0 through a softplus of O(1) parameters in per-joint units (b in kd_i, μ in 5 % of the effort
limit, Δa in the nominal armature or 0.01 kg·m²), so Adam moves every term at a comparable rate. It has the interface of :class:`~wresdyn.learn.residual.ResidualPolicy`
(``kind == "torque"``), so it is fitted by the same gradient machinery (:func:`wresdyn.fit.gradfit.fit` with
``arch="parametric"``) and evaluated identically. The armature term uses the observed q̈ (one step old), an
explicit stand-in for a mass-matrix change; the other terms are exact in form.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn as nn

__all__ = ["ParametricResidual", "COULOMB_SMOOTHING"]

COULOMB_SMOOTHING = 0.05
"""v_s [rad/s]: the tanh friction reaches 76 % of μ at 0.05 rad/s, well below the excitation's joint speeds."""


def _inv_softplus(x: float) -> float:
    return float(np.log(np.expm1(x)))


class ParametricResidual(nn.Module):
    """Per-joint PD gain scales, viscous damping [N·m·s/rad], Coulomb friction [N·m] and armature [kg·m²]."""

    def __init__(self, robot, effort_scale) -> None:
        super().__init__()
        self.kind = "torque"
        self.v_s = COULOMB_SMOOTHING
        n = robot.n_dof
        self.register_buffer("kp", torch.as_tensor(robot.kp, dtype=torch.float32))
        self.register_buffer("kd", torch.as_tensor(robot.kd, dtype=torch.float32))
        self.register_buffer("scale", torch.as_tensor(effort_scale, dtype=torch.float32))
        # same interface as ResidualPolicy (raw observation in); the physical model needs no normalisation
        self.register_buffer("obs_mean", torch.zeros(4 * n))
        self.register_buffer("obs_std", torch.ones(4 * n))
        self.n = n
        effort = np.where(np.isfinite(robot.effort), robot.effort, 100.0)
        self.register_buffer("damping_unit", torch.as_tensor(np.maximum(robot.kd, 1e-2), dtype=torch.float32))
        self.register_buffer("friction_unit", torch.as_tensor(0.05 * effort, dtype=torch.float32))
        self.register_buffer("armature_unit", torch.as_tensor(np.where(robot.armature > 0, robot.armature, 0.01), dtype=torch.float32))
        self.log_kp_scale = nn.Parameter(torch.zeros(n))
        self.log_kd_scale = nn.Parameter(torch.zeros(n))
        # start at small extra damping, friction and armature (5 % of a unit), where softplus still has slope
        start = _inv_softplus(0.05)
        self.raw_damping = nn.Parameter(torch.full((n,), start))
        self.raw_friction = nn.Parameter(torch.full((n,), start))
        self.raw_armature = nn.Parameter(torch.full((n,), start))

    def parameters_physical(self) -> dict[str, np.ndarray]:
        """The identified parameters in SI units, each shape (n_dof,)."""
        f = nn.functional.softplus
        with torch.no_grad():
            return {
                "kp_scale": torch.exp(self.log_kp_scale).cpu().numpy(),
                "kd_scale": torch.exp(self.log_kd_scale).cpu().numpy(),
                "damping": (self.damping_unit * f(self.raw_damping)).cpu().numpy(),
                "friction": (self.friction_unit * f(self.raw_friction)).cpu().numpy(),
                "armature": (self.armature_unit * f(self.raw_armature)).cpu().numpy(),
            }

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        n = self.n
        q, qd, qdd, q_cmd = obs[:, :n], obs[:, n : 2 * n], obs[:, 2 * n : 3 * n], obs[:, 3 * n :]
        f = nn.functional.softplus
        tau = (torch.exp(self.log_kp_scale) - 1.0) * self.kp * (q_cmd - q) - (torch.exp(self.log_kd_scale) - 1.0) * self.kd * qd
        tau = tau - self.damping_unit * f(self.raw_damping) * qd
        tau = tau - self.friction_unit * f(self.raw_friction) * torch.tanh(qd / self.v_s)
        tau = tau - self.armature_unit * f(self.raw_armature) * qdd
        return torch.clamp(tau, -self.scale, self.scale)

    def reset(self) -> None:
        pass

    def residual_kind(self) -> str:
        return self.kind
