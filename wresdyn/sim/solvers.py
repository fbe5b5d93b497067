"""Newton simulation set-up for replaying joint commands under PD control.

Solvers (``solver=`` everywhere in wresdyn):

- ``"replay"``: :class:`wresdyn.sim.replay.SolverReplay`, this project's Newton solver for the replay workload
  (fixed base, PD drives with implicit damping as MuJoCo's ``implicitfast``, armature, friction, limits,
  residual torque; one fused kernel per step, differentiable by Warp's Tape). The default (``"auto"``) for
  fixed-base robots: 200-800x faster than Featherstone on the CPU, 2.6e-7 rad from MuJoCo C over 2 s.
- ``"featherstone"``: Newton's ``SolverFeatherstone``, differentiable, floating base too. It applies the PD
  drive explicitly (newton issue 4269), so it is stable only while each joint's damping and stiffness are
  small against the inertia that joint feels, ``kd·dt / m_eff < 2`` and ``kp·dt² / m_eff < 4`` for
  semi-implicit Euler on m ẍ = −kp x − kd ẋ, with ``m_eff = 1 / (M⁻¹)_ii`` (armature included).
  :func:`explicit_pd_margin` computes the criterion; reflected rotor inertia keeps real humanoids inside it
  at 500 Hz, a robot file without armature and with high damping is not.
- ``"mujoco"``: Newton's ``SolverMuJoCo`` (implicit PD; mujoco_warp on CUDA, MuJoCo C on CPU), not
  differentiable.

``"auto"`` picks ``replay`` on a fixed base; on a floating base, Featherstone when the explicit-PD criterion
holds with a 2x margin, else ``mujoco``.
"""

from __future__ import annotations

import warnings

import numpy as np

from ..errors import SimulationDiverged
from ..robot.description import Robot

__all__ = ["SOLVERS", "explicit_pd_margin", "resolve_solver", "make_solver", "replay", "SimulationDiverged"]

SOLVERS = ("auto", "replay", "featherstone", "mujoco")
"""Replay solvers (see the module docstring)."""


def explicit_pd_margin(robot: Robot, dt: float, q: np.ndarray | None = None) -> np.ndarray:
    """Per-joint stability ratio of explicit PD under semi-implicit Euler; < 1 is stable.

    max(kd·dt / (2 m_eff), kp·dt² / (4 m_eff)) with m_eff = 1 / (M⁻¹)_ii at configuration ``q``
    (default: the neutral pose). Shape (n_dof,).
    """
    import pinocchio as pin

    from ..robot.pinocchio_model import build_pinocchio

    model = build_pinocchio(robot)
    data = model.createData()
    qf = pin.neutral(model)
    qf[model.nq - robot.n_dof :] = robot.q0 if q is None else q
    minv = pin.computeMinverse(model, data, qf)
    minv = np.triu(minv) + np.triu(minv, 1).T
    m_eff = 1.0 / np.diag(minv)[model.nv - robot.n_dof :]
    return np.maximum(robot.kd * dt / (2.0 * m_eff), robot.kp * dt * dt / (4.0 * m_eff))


def resolve_solver(robot: Robot, dt: float, kind: str = "auto") -> str:
    """The concrete solver kind for ``kind`` (see the module docstring for "auto")."""
    if kind not in SOLVERS:
        raise ValueError(f"unknown solver {kind!r}; choose from {SOLVERS}")
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


def make_solver(model, robot: Robot, dt: float, kind: str = "auto"):
    """Create the Newton solver for replay. See the module docstring for the choice."""
    import newton

    kind = resolve_solver(robot, dt, kind)
    if kind == "replay":
        from .replay import SolverReplay

        return SolverReplay(model)
    if kind == "featherstone":
        return newton.solvers.SolverFeatherstone(model)
    cpu = not str(model.device).startswith("cuda")
    return newton.solvers.SolverMuJoCo(model, use_mujoco_cpu=cpu, disable_contacts=True, integrator="implicitfast")


def replay(
    robot: Robot,
    q_cmd: np.ndarray,
    q0: np.ndarray,
    qd0: np.ndarray | None = None,
    dt: float = 0.002,
    solver: str = "auto",
    tau_res: np.ndarray | None = None,
    device: str | None = "cpu",
) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop PD replay of joint commands in Newton, one world per trajectory.

    Args:
        robot: The robot.
        q_cmd: Commanded joint positions [rad], shape (T, n_dof) or (W, T, n_dof).
        q0: Initial joint positions [rad], shape (n_dof,) or (W, n_dof).
        qd0: Initial joint velocities [rad/s], same shape as ``q0`` (default zero).
        dt: Time step [s]; command k is held during step k.
        solver: One of :data:`SOLVERS`.
        tau_res: Optional residual joint torque [N*m] added each step, shape like ``q_cmd``.
        device: Warp device.

    Returns:
        ``(q, qd)``, each shape (T + 1, n_dof) or (W, T + 1, n_dof): the initial state, then the state after
        each step.

    Raises:
        SimulationDiverged: the state became non-finite.
    """
    import warp as wp

    single = q_cmd.ndim == 2
    q_cmd = np.atleast_3d(q_cmd[None] if single else q_cmd)
    w, t_len, n = q_cmd.shape
    q0 = np.broadcast_to(q0, (w, n))
    qd0 = np.zeros((w, n)) if qd0 is None else np.broadcast_to(qd0, (w, n))
    model = robot.build_model(w, device)
    sim = make_solver(model, robot, dt, solver)
    s0, s1, ctrl = model.state(), model.state(), model.control()
    nq, nqd = model.joint_coord_count // w, model.joint_dof_count // w
    jq, jqd = s0.joint_q.numpy().reshape(w, nq), s0.joint_qd.numpy().reshape(w, nqd)
    jq[:, robot.q_index], jqd[:, robot.qd_index] = q0, qd0
    s0.joint_q.assign(jq.ravel())
    s0.joint_qd.assign(jqd.ravel())
    import newton

    newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    target = np.zeros((w, nqd), dtype=np.float32)
    force = np.zeros((w, nqd), dtype=np.float32)
    out_q = np.empty((w, t_len + 1, n))
    out_qd = np.empty((w, t_len + 1, n))
    out_q[:, 0], out_qd[:, 0] = q0, qd0
    for k in range(t_len):
        target[:, robot.qd_index] = q_cmd[:, k]
        ctrl.joint_target_q.assign(target.ravel())
        if tau_res is not None:
            force[:, robot.qd_index] = np.asarray(tau_res).reshape(w, t_len, n)[:, k]
            ctrl.joint_f.assign(force.ravel())
        sim.step(s0, s1, ctrl, None, dt)
        s0, s1 = s1, s0
        out_q[:, k + 1] = s0.joint_q.numpy().reshape(w, nq)[:, robot.q_index]
        out_qd[:, k + 1] = s0.joint_qd.numpy().reshape(w, nqd)[:, robot.qd_index]
        if not np.isfinite(out_q[:, k + 1]).all():
            raise SimulationDiverged(f"{robot.source.name}: Newton replay diverged at step {k + 1} (t = {(k + 1) * dt:.3f} s)")
    wp.synchronize()
    return (out_q[0], out_qd[0]) if single else (out_q, out_qd)
