"""The friction-loss constraint's parameters of the MJCF export (:mod:`.mjcf`): MuJoCo's soft friction made wresdyn's.

MuJoCo's ``frictionloss`` row of a DoF has the regulariser ``R = (1 - d) / d / m0_mj`` (``d = solimpfriction[0]``,
the impedance at zero violation; ``m0_mj = 1 / dof_invweight0``, the DoF's effective inertia at the reference pose
of the model MuJoCo compiled) and the reference acceleration ``-b v``, ``b = 2 / (dmax timeconst)`` (``dmax =
solimpfriction[1]``, ``timeconst = solreffriction[0]``). wresdyn's replay solver writes the same constraint with
MuJoCo's default ``d0``, ``dmax``, ``timeconst`` but fixes ``m0`` from the robot as built, the robot file's values,
before identified masses and armature are written into it (:mod:`wresdyn.sim.solver_replay.solver`). An identified
robot therefore has another ``m0`` in MuJoCo than in wresdyn; the export keeps ``b`` and moves ``d`` per joint so
that ``d / (1 - d) m0_mj`` is wresdyn's ``d0 / (1 - d0) m0`` (:func:`soft_friction`). The damper law has no such
``m0`` in wresdyn (``-clamp(kappa H_ii v, -mu, mu)``): :func:`damper_friction`.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["MJ_SOLIMP_FRICTION", "MJ_SOLREF_FRICTION", "damper_friction", "reference_inertia", "soft_friction"]

MJ_SOLIMP_FRICTION = (0.9, 0.95, 0.001, 0.5, 2.0)
"""MuJoCo's default ``solimp`` (``d0``, ``dmax``, width [rad], midpoint, power): the soft friction of wresdyn's replay
solver is MuJoCo's with these."""
MJ_SOLREF_FRICTION = (0.02, 1.0)
"""MuJoCo's default ``solref`` (``timeconst`` [s], damping ratio), the replay solver's too."""
_MJ_IMP_MAX = 0.9999
"""MuJoCo's largest impedance (``mjMAXIMP``): a larger ``solimp`` is clipped to it."""


def damper_friction(friction_kappa: float, dt: float) -> tuple[list[float], list[float]]:
    """MuJoCo's friction-loss constraint parameters (``solref_friction``, ``solimp_friction``) that make it the
    replay's damper law ``-clamp(kappa H_ii v, -mu, mu)`` on the new velocity: MuJoCo's soft friction is that
    damper with ``c = d / (1 - d)`` (its impedance ``d``, times ``m0_i / H_ii``, 1 at the reference pose) on
    ``v - (1 - b dt) qd`` with ``b = 2 / (d timeconst)`` (:mod:`wresdyn.sim.solver_replay.step_terms`), so
    ``d = kappa dt / (1 + kappa dt)`` and ``timeconst = 2 dt / d`` (no pull toward the old velocity) give it (d at most
    0.9999, MuJoCo's bound)."""
    c = friction_kappa * dt
    d = min(c / (1.0 + c), _MJ_IMP_MAX) if math.isfinite(c) else _MJ_IMP_MAX
    return [2.0 * dt / d, 1.0], [d, d, 0.001, 0.5, 2.0]


def reference_inertia(spec, joint_names) -> np.ndarray:
    """Each joint's effective inertia at the reference pose, ``1 / dof_invweight0`` [kg m^2 or kg] of ``spec``
    compiled (armature included), shape (n_joints,): the scale MuJoCo gives the joint's friction regulariser."""
    model = spec.compile()
    return np.array([1.0 / float(model.dof_invweight0[model.joint(n).dofadr[0]]) for n in joint_names])


def soft_friction(m0_wresdyn: np.ndarray, m0_mujoco: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per joint the ``solimpfriction`` (shape (n, 5)) that gives MuJoCo's soft friction wresdyn's regulariser:
    ``d / (1 - d) = d0 / (1 - d0) m0_wresdyn / m0_mujoco`` (both (n,), the reference inertias of the robot as built
    and of the exported model), ``dmax`` and the default ``solreffriction`` kept, so the reference damping ``b`` is
    unchanged. Also returns which joints hit MuJoCo's bound 0.9999 (shape (n,), bool): there the match is lost."""
    d0 = MJ_SOLIMP_FRICTION[0]
    c = d0 / (1.0 - d0) * np.asarray(m0_wresdyn, dtype=np.float64) / np.asarray(m0_mujoco, dtype=np.float64)
    d = c / (1.0 + c)
    clipped = d > _MJ_IMP_MAX
    imp = np.tile(np.asarray(MJ_SOLIMP_FRICTION), (len(d), 1))
    imp[:, 0] = np.minimum(d, _MJ_IMP_MAX)
    return imp, clipped
