"""Newton simulation set-up for replaying joint commands under PD control.

Solvers (``solver=`` everywhere in wresdyn):

- ``"replay"``: :class:`wresdyn.sim.solver_replay.SolverReplay`, this project's Newton solver for the replay workload
  (fixed base, PD drives with implicit damping as MuJoCo's ``implicitfast``, armature, friction, limits,
  residual torque; one fused kernel per step, differentiable by Warp's Tape). The default (``"auto"``) for
  fixed-base robots: 200-800x faster than Featherstone on the CPU, 2.6e-7 rad from MuJoCo C over 2 s.
- ``"featherstone"``: Newton's ``SolverFeatherstone``, differentiable, floating base too. It applies the PD
  drive explicitly (newton issue 4269), so it is stable only while each joint's damping and stiffness are
  small against the inertia that joint feels, ``kd·dt / m_eff < 2`` and ``kp·dt² / m_eff < 4`` for
  semi-implicit Euler on m ẍ = −kp x − kd ẋ, with ``m_eff = 1 / (M⁻¹)_ii`` (armature included).
  :func:`explicit_pd_margin` computes the criterion; reflected rotor inertia keeps real humanoids inside it
  at 500 Hz, a robot file without armature and with high damping is not.
- ``"mujoco"``: Newton's ``SolverMuJoCo`` (implicit PD; mujoco_warp on CUDA; on the CPU MuJoCo C for one world
  and, since Newton's MuJoCo C backend simulates one world only, mujoco_warp on Warp's CPU device for several, or
  with a ground :class:`~wresdyn.sim.solver_threads.SolverMuJoCoThreads`: Newton's MuJoCo C model of the robot
  stepped for every world in C threads), not differentiable. The only one of the three that feels a ground: MuJoCo's own collision detection and soft
  contact constraints, with :class:`~wresdyn.robot.ground.ContactSettings`.

``"auto"`` picks ``replay`` on a fixed base; on a floating base, Featherstone when the explicit-PD criterion
holds with a 2x margin, else ``mujoco``; with a ground, ``mujoco``. A ground with ``replay`` (no contacts, fixed
base) or ``featherstone`` is refused: SolverFeatherstone feels contacts only as penalty forces (explicit
springs from the shapes' ``ke``/``kd``/``kf``/``mu``) computed from a Newton ``Contacts`` buffer passed to its
``step`` (``model.collide`` each step); the simulator passes none, so the robot would fall through the floor, and
penalty springs would not be MuJoCo's soft-constraint contact of the real robot either.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..choices import SolverKind, check_choice, choices
from ..errors import WresdynError
from ..robot.contact import ContactSettings
from ..robot.description import Robot
from ..robot.pinocchio_model import build_pinocchio
from .floor_budget import collision_shapes_newton, floor_budget
from .solver_threads import SolverMuJoCoThreads

__all__ = ["SOLVERS", "explicit_pd_margin", "floor_solver", "resolve_solver", "make_solver"]

SOLVERS = choices(SolverKind)
"""Replay solvers (see the module docstring)."""


def explicit_pd_margin(robot: Robot, dt: float, q: np.ndarray | None = None) -> np.ndarray:
    """Per-joint stability ratio of explicit PD under semi-implicit Euler; < 1 is stable.

    max(kd·dt / (2 m_eff), kp·dt² / (4 m_eff)) with m_eff = 1 / (M⁻¹)_ii at configuration ``q``
    (default: the neutral pose). Shape (n_dof,).
    """
    import pinocchio as pin

    model = build_pinocchio(robot)
    data = model.createData()
    qf = pin.neutral(model)
    qf[model.nq - robot.n_dof :] = robot.q0 if q is None else q
    minv = pin.computeMinverse(model, data, qf)
    minv = np.triu(minv) + np.triu(minv, 1).T
    m_eff = 1.0 / np.diag(minv)[model.nv - robot.n_dof :]
    return np.maximum(robot.kd * dt / (2.0 * m_eff), robot.kp * dt * dt / (4.0 * m_eff))


def resolve_solver(robot: Robot, dt: float, kind: str = "auto", ground: bool = False) -> str:
    """The concrete solver kind for ``kind`` (see the module docstring for "auto"); with a ``ground``, ``mujoco``
    or a one-line :class:`ValueError`."""
    check_choice(kind, SolverKind, "solver")
    if ground:
        if kind not in ("auto", "mujoco"):
            raise ValueError(f"{robot.source.name}: a ground needs solver 'mujoco' (or 'auto'); the {kind} solver "
                             "would not feel it")
        return "mujoco"
    if kind == "auto" and robot.base == "fixed":
        return "replay"
    if kind not in ("auto", "featherstone"):
        return kind
    margin = explicit_pd_margin(robot, dt)
    worst = int(np.argmax(margin))
    if margin[worst] <= 0.5:
        return "featherstone"
    msg = (f"{robot.source.name}: explicit PD is near or past its stability limit at dt={dt} s on "
           f"{robot.joint_names[worst]} (ratio {margin[worst]:.2f}; add armature or lower kd)")
    if kind == "featherstone":
        warnings.warn(msg + "; SolverFeatherstone may diverge", stacklevel=3)
        return "featherstone"
    return "mujoco"


def make_solver(model, robot: Robot, dt: float, kind: str = "auto", *, ground: bool = False, contact=None,
                friction_kappa: float | None = None, threads: int = 1):
    """Create the Newton solver for replay. See the module docstring for the choice.

    ``friction_kappa``: the replay solver's dry-friction law (``SolverReplay(friction_kappa=)``): ``None``, the soft
    default, or the rate [1/s] of its damper law; any other solver with a rate is a one-line :class:`WresdynError`.

    ``ground``: the model has a floor (``Robot.build_model(ground=True)``): SolverMuJoCo with contacts on and the
    solver options of ``contact`` (:class:`~wresdyn.robot.ground.ContactSettings`, default ``ContactSettings()``),
    the same as :func:`wresdyn.robot.mujoco_model.build_mujoco` writes for the MuJoCo C robot.

    ``threads``: the replay solver's host threads on the CPU (``SolverReplay(threads=)``); the others ignore it.
    """
    import newton

    kind = resolve_solver(robot, dt, kind, ground)
    if friction_kappa is not None and kind != "replay":
        raise WresdynError(f"{robot.source.name}: friction_kappa is a law of the replay solver, not of {kind}")
    if kind == "replay":
        from .solver_replay import SolverReplay

        return SolverReplay(model, friction_kappa=friction_kappa, threads=threads)
    if kind == "featherstone":
        return newton.solvers.SolverFeatherstone(model)
    # Newton's MuJoCo C backend holds one world; several run on mujoco_warp, on the CPU too (Warp's CPU device)
    mujoco_c = not str(model.device).startswith("cuda") and model.world_count == 1
    if not ground:
        return newton.solvers.SolverMuJoCo(model, use_mujoco_cpu=mujoco_c, disable_contacts=True,
                                           integrator="implicitfast")
    if not str(model.device).startswith("cuda") and model.world_count > 1:
        return SolverMuJoCoThreads(model, robot, contact)

    return floor_solver(model, contact, use_mujoco_cpu=mujoco_c)


def floor_solver(model, contact=None, *, use_mujoco_cpu: bool = False):
    """Newton's ``SolverMuJoCo`` for a model with a floor (``Robot.build_model(ground=True)``): MuJoCo's contacts
    on, the options of ``contact`` (:class:`~wresdyn.robot.contact.ContactSettings`, default ``ContactSettings()``),
    ``implicitfast``. On mujoco_warp (``use_mujoco_cpu=False``: CUDA, or Warp's CPU device) its contacts and
    constraint rows per world are sized by :func:`~wresdyn.sim.floor_budget.floor_budget` for the worst state and
    any dry friction drawn later, not from the model as built (see :mod:`wresdyn.sim.floor_budget`); MuJoCo C
    (``use_mujoco_cpu=True``, one world) grows its own and only reads ``nconmax`` as the contacts it exports."""
    import newton

    c = contact or ContactSettings()
    nconmax, njmax = floor_budget(collision_shapes_newton(model), model.joint_dof_count // max(model.world_count, 1))
    return newton.solvers.SolverMuJoCo(model, use_mujoco_cpu=use_mujoco_cpu, disable_contacts=False,
                                       integrator="implicitfast", solver=c.solver, cone=c.cone,
                                       iterations=c.iterations, ls_iterations=c.ls_iterations, impratio=c.impratio,
                                       enable_multiccd=False, nconmax=nconmax, njmax=njmax)
