"""The friction-loss constraint's parameters of the MJCF export (:mod:`.mjcf`): MuJoCo's soft friction made wresdyn's.

MuJoCo's ``frictionloss`` row of a DoF has the regulariser ``R = (1 - d) / d / m0_mj`` (``d = solimpfriction[0]``,
the impedance at zero violation; ``m0_mj = 1 / dof_invweight0``, the DoF's effective inertia at the reference pose
of the model MuJoCo compiled) and the reference acceleration ``-b v``, ``b = 2 / (dmax timeconst)`` (``dmax =
solimpfriction[1]``, ``timeconst = solreffriction[0]``). wresdyn's replay solver writes the same constraint with
MuJoCo's default ``d0``, ``dmax``, ``timeconst`` but fixes ``m0`` from the robot as built, the robot file's values,
before identified masses and armature are written into it (:mod:`wresdyn.sim.solver_replay.solver`). An identified
robot therefore has another ``m0`` in MuJoCo than in wresdyn; the export keeps ``b`` and moves ``d`` per joint so
that ``d / (1 - d) m0_mj`` is wresdyn's ``d0 / (1 - d0) m0`` (:func:`soft_friction`). The damper law has no such
``m0`` in wresdyn (``-clamp(kappa H_ii v, -mu, mu)``); MuJoCo's ``m0_mj / H_ii`` is taken out at the reference
pose instead (:func:`damper_friction`).
"""

from __future__ import annotations

import numpy as np

__all__ = ["MJ_SOLIMP_FRICTION", "MJ_SOLREF_FRICTION", "damper_friction", "reference_inertia", "soft_friction"]

MJ_SOLIMP_FRICTION = (0.9, 0.95, 0.001, 0.5, 2.0)
"""MuJoCo's default ``solimp`` (``d0``, ``dmax``, width [rad], midpoint, power): the soft friction of wresdyn's replay
solver is MuJoCo's with these."""
MJ_SOLREF_FRICTION = (0.02, 1.0)
"""MuJoCo's default ``solref`` (``timeconst`` [s], damping ratio), the replay solver's too."""
_MJ_IMP_MAX = 0.9999
"""MuJoCo's largest impedance (``mjMAXIMP``): a larger ``solimp`` is clipped to it."""


def damper_friction(friction_kappa: float, dt: float, coupling=1.0) -> tuple[list[float], list[float]]:
    """MuJoCo's friction-loss constraint parameters (``solref_friction``, ``solimp_friction``) that make it the
    replay's damper law ``-clamp(kappa H_ii v, -mu, mu)`` on the new velocity: MuJoCo's soft friction is that
    damper with ``c = d / (1 - d) m0_i / H_ii`` (its impedance ``d``) on ``v - (1 - b dt) qd`` with
    ``b = 2 / (d timeconst)`` (:mod:`wresdyn.sim.solver_replay.step_terms`), so ``d / (1 - d) = kappa dt H_ii / m0_i``
    and ``timeconst = 2 dt / d`` (no pull toward the old velocity) give it at the reference pose (d at most 0.9999,
    MuJoCo's bound). ``coupling``: ``H_ii / m0_i`` there (:func:`reference_inertia`), at least 1, 1 for a joint
    that does not couple to others; a scalar or shape (n,), as the results' entries ([timeconst, 1] and the 5
    solimp numbers, each a scalar or (n,))."""
    c = friction_kappa * dt * np.asarray(coupling, dtype=np.float64)
    d = np.where(np.isfinite(c), np.minimum(c / (1.0 + np.where(np.isfinite(c), c, 0.0)), _MJ_IMP_MAX), _MJ_IMP_MAX)
    d = float(d) if d.ndim == 0 else d
    return [2.0 * dt / d, 1.0], [d, d, 0.001, 0.5, 2.0]


def reference_inertia(spec, joint_names) -> tuple[np.ndarray, np.ndarray]:
    """Each joint's effective inertia at the reference pose, ``m0 = 1 / dof_invweight0`` [kg m^2 or kg] of ``spec``
    compiled (armature included): the scale MuJoCo gives the joint's friction regulariser; and the diagonal of the
    joint-space inertia there, ``H_ii``; both shape (n_joints,)."""
    import mujoco

    model = spec.compile()
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    dofs = [int(model.joint(n).dofadr[0]) for n in joint_names]
    return 1.0 / model.dof_invweight0[dofs], np.diag(full)[dofs].copy()


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
