"""The simulator's own physical parameters as fitted quantities: per joint and per link, physically consistent.

What the grey-box identification (:mod:`wresdyn.identify.sysid`) fits and what a calibrated robot carries, in the
units of the Newton model arrays that :class:`~wresdyn.sim.solver_replay.SolverReplay` reads every launch:

========================  =========================  =====================================================
field                     shape, unit                model array (per world)
========================  =========================  =====================================================
``kp``, ``kd``            (n,) N·m/rad, N·m·s/rad    ``joint_target_ke``, ``joint_target_kd``
``armature``              (n,) kg·m²                 ``joint_armature``
``damping``               (n,) N·m·s/rad             ``joint_damping`` (viscous)
``friction``              (n,) N·m                   ``joint_friction`` (dry friction with stiction)
``effort``                (n,) N·m                   ``joint_effort_limit`` (the drive saturates there)
``delay``                 (n,) s                     the command path (:class:`~wresdyn.sim.bank.TrajectoryBank`)
``deadband``              (n,) rad                   ``joint_servo_deadband`` (servo joints: dead band b)
``noload_speed``          (n,) rad/s                 ``joint_servo_noload_speed`` (servo joints: motor w0)
``goal_accel``            (n,) rad/s²                the command path (servo joints: goal profile a_max)
``startup_torque``        (n,) N·m                   ``joint_servo_startup_torque`` (servo joints: least drive u0)
``stiction``              (n,) N·m                   ``joint_servo_stiction`` (servo joints: static friction above dry)
``backlash``              (n,) rad                   ``joint_servo_backlash`` (servo joints: gear play beta)
``encoder_offset``        (n,) rad                   ``joint_servo_encoder_offset`` (servo joints: encoder zero o)
``load_friction``         (n,) -                     ``joint_servo_load_friction`` (servo joints: friction / torque)
``body_mass``             (nb,) kg                   ``body_mass``
``body_com``              (nb, 3) m, body frame      ``body_com``
``body_inertia``          (nb, 3, 3) kg·m², at com   ``body_inertia``
========================  =========================  =====================================================

:class:`~wresdyn.robot.physical.PhysicalParams` holds the values (numpy, float64) and reads/writes them as JSON
(never a pickle); :class:`PhysicsModel` is the torch module that produces them from unconstrained coordinates:

On a servo joint (:mod:`wresdyn.robot.servo`) ``kp``, ``kd`` are the servo's position-loop gains in torque units and
``effort`` its stall torque U; the servo law reads the three servo fields, which PD joints ignore.

- gains, armature, mass, no-load speed, goal acceleration: ``nominal · exp(u)`` (positive, scale-free steps; a
  nominal 0 stays 0: no torque-speed line, no profile);
- damping, friction, effort, delay, dead band, startup torque, stiction, backlash and load friction: ``reference · u``
  with ``u`` projected onto ``u ≥ 0`` (:meth:`PhysicsModel.project`) so a zero nominal value can be left and reached
  again;
- the encoder offset: ``reference · u``, signed (not projected);
- each link's mass, centre of mass and inertia through the log-Cholesky factor of its 4×4 pseudo-inertia
  ``J = [[Σ, h], [hᵀ, m]] = U Uᵀ`` (Rucker & Wensing 2022), ``Σ = ∫ r rᵀ dm`` about the body origin and
  ``h = m c``: every ``U`` with a positive diagonal gives a physically realisable body (positive mass, the
  triangle inequalities of the principal moments), so no fitted value can leave physics.
"""

from __future__ import annotations

import numpy as np
import torch

from ..robot.physical import BODY_FIELDS, JOINT_FIELDS, SERVO_FIELDS, PhysicalParams, PhysicsError

__all__ = ["JOINT_FIELDS", "SERVO_FIELDS", "BODY_FIELDS", "PhysicalParams", "PhysicsModel", "PhysicsError",
           "pseudo_inertia", "from_pseudo_inertia"]

MODEL_ARRAYS = {"kp": "joint_target_ke", "kd": "joint_target_kd", "armature": "joint_armature",
                "damping": "joint_damping", "friction": "joint_friction", "effort": "joint_effort_limit",
                "body_mass": "body_mass", "body_com": "body_com", "body_inertia": "body_inertia"}
"""Newton model array of each field (``delay`` is the command path's, not the model's)."""
SERVO_ARRAYS = {"deadband": "joint_servo_deadband", "noload_speed": "joint_servo_noload_speed",
                "startup_torque": "joint_servo_startup_torque", "stiction": "joint_servo_stiction",
                "backlash": "joint_servo_backlash", "encoder_offset": "joint_servo_encoder_offset",
                "load_friction": "joint_servo_load_friction"}
"""Model array of each servo field, present on models of robots with servo joints
(:func:`wresdyn.robot.servo.attach_servo`; ``goal_accel`` is the command path's)."""
DEADBAND_REF = 0.01
"""Unit of the dead band's coordinate [rad] (the SO-101's joints stop 8-36 mrad short of a target)."""
LOAD_FRICTION_REF = 0.1
"""Unit of the load friction's coordinate [-]: a tenth of the carried torque, a geared servo's mesh losses at 90 %
efficiency."""
_LOG_FIELDS = ("kp", "kd", "armature", "noload_speed", "goal_accel")
"""Joint fields with the coordinate ``nominal · exp(u)``."""


def pseudo_inertia(mass, com, inertia):
    """4×4 pseudo-inertia ``J = [[Σ, m c], [m cᵀ, m]]``, ``Σ = ½ tr(I_o) 1 − I_o``, ``I_o`` the inertia about the
    body origin. Torch or numpy: mass (...,), com (..., 3), inertia about the com (..., 3, 3)."""
    xp = torch if torch.is_tensor(mass) else np
    eye = xp.eye(3, dtype=inertia.dtype) if xp is np else torch.eye(3, dtype=inertia.dtype, device=inertia.device)
    c = com[..., :, None]
    cc = (c * c.swapaxes(-1, -2)) if xp is np else c @ c.transpose(-1, -2)
    m = mass[..., None, None]
    i_o = inertia + m * ((com * com).sum(-1)[..., None, None] * eye - cc)
    tr = xp.diagonal(i_o, axis1=-2, axis2=-1).sum(-1) if xp is np else torch.diagonal(i_o, dim1=-2, dim2=-1).sum(-1)
    sigma = 0.5 * tr[..., None, None] * eye - i_o
    h = mass[..., None] * com
    top = xp.concatenate([sigma, h[..., :, None]], -1) if xp is np else torch.cat([sigma, h[..., :, None]], -1)
    bottom = xp.concatenate([h, mass[..., None]], -1)[..., None, :] if xp is np else \
        torch.cat([h, mass[..., None]], -1)[..., None, :]
    return xp.concatenate([top, bottom], -2) if xp is np else torch.cat([top, bottom], -2)


def from_pseudo_inertia(j: torch.Tensor):
    """Inverse of :func:`pseudo_inertia` (torch): ``J`` (..., 4, 4) -> (mass, com, inertia about the com)."""
    m = j[..., 3, 3]
    c = j[..., :3, 3] / m[..., None]
    sigma_c = j[..., :3, :3] - m[..., None, None] * (c[..., :, None] @ c[..., None, :])
    eye = torch.eye(3, dtype=j.dtype, device=j.device)
    tr = torch.diagonal(sigma_c, dim1=-2, dim2=-1).sum(-1)
    return m, c, tr[..., None, None] * eye - sigma_c


def _upper_cholesky(j: np.ndarray) -> np.ndarray:
    """Upper-triangular ``U`` with ``U Uᵀ = J`` (positive diagonal), for a batch (..., 4, 4)."""
    p = np.eye(4)[::-1]
    return p @ np.linalg.cholesky(p @ j @ p) @ p


class PhysicsModel(torch.nn.Module):
    """Unconstrained coordinates -> :class:`PhysicalParams` values as torch tensors (module docstring).

    Args:
        robot: The robot (nominal values, names, which bodies move).
        start: Values to start from (default the robot's nominal ones); the exp-parametrised fields are
            relative to them, the linear ones measured in the reference units below.
        fit: Fields to fit (default all of :data:`JOINT_FIELDS` and ``"bodies"``; :data:`SERVO_FIELDS` only when
            named); the others stay at ``start``.
        dt: Sample period [s]; the delay's unit.
        effort_floor: Least effort limit :meth:`project` keeps, as a fraction of the robot's finite limits
            (``None``: 0.05 of them).
        shared_delay: One command delay for every joint (the mean of the per-joint coordinates, so each joint's
            gradient is the shared one's and they move together), for a command path whose latency is the bus's,
            the same on every joint.
    """

    def __init__(self, robot, start: PhysicalParams | None = None, fit=None, dt: float = 0.002,
                 effort_floor: float | None = None, shared_delay: bool = False) -> None:
        super().__init__()
        start = start or PhysicalParams.nominal(robot)
        start.check(robot)
        self.robot, self.start, self.dt = robot, start, float(dt)
        self.shared_delay = bool(shared_delay)
        self.fit = set(fit or (*JOINT_FIELDS, "bodies"))
        f64 = dict(dtype=torch.float64)
        n = robot.n_dof
        kd, eff = np.asarray(robot.kd, float), np.asarray(robot.effort, float)
        eff_ref = np.where(np.isfinite(eff), eff, 10.0 * np.maximum(robot.kp, 1.0))
        # linear fields: value = ref * u, u >= 0; references make u ~ O(0.1-1)
        self.ref = {"damping": kd, "friction": 0.05 * eff_ref, "effort": eff_ref, "delay": np.full(n, self.dt)}
        for f, r in self.ref.items():
            self.register_buffer(f"ref_{f}", torch.as_tensor(r, **f64))
        # not persistent: a setting of the fit, not a fitted state (checkpoints keep their keys); a buffer, so that it
        # moves with the model (a captured step's projection reads it on the device)
        self.register_buffer("effort_floor", None if effort_floor is None else torch.as_tensor(
            np.where(np.isfinite(eff), max(float(effort_floor), 0.05), 0.05), **f64), persistent=False)
        for f in ("kp", "kd", "armature"):
            self.register_buffer(f"start_{f}", torch.as_tensor(getattr(start, f), **f64))
            self.register_parameter(f"u_{f}", torch.nn.Parameter(torch.zeros(n, **f64), f in self.fit))
        for f, r in self.ref.items():
            s = getattr(start, f)
            u0 = np.where(np.isfinite(s), s, r) / r  # an unlimited effort starts at the reference
            self.register_parameter(f"u_{f}", torch.nn.Parameter(torch.as_tensor(u0, **f64), f in self.fit))
        # links that move (mass > 0 and not welded to the world)
        moving = np.array([m > 0 and _moves(robot, b) for b, m in enumerate(start.body_mass)])
        self.register_buffer("moving", torch.as_tensor(np.flatnonzero(moving)))
        j = pseudo_inertia(start.body_mass[moving], start.body_com[moving], start.body_inertia[moving])
        u = _upper_cholesky(j)
        diag = np.log(np.diagonal(u, axis1=-2, axis2=-1))
        self.register_buffer("triu", torch.as_tensor(np.stack(np.triu_indices(4, 1)), dtype=torch.long))
        off = u[:, self.triu[0].numpy(), self.triu[1].numpy()]
        bodies = "bodies" in self.fit
        self.u_body_logdiag = torch.nn.Parameter(torch.as_tensor(diag, **f64), bodies)
        self.u_body_off = torch.nn.Parameter(torch.as_tensor(off, **f64), bodies)
        self.register_buffer("u0_body_logdiag", self.u_body_logdiag.detach().clone())
        self.register_buffer("u0_body_off", self.u_body_off.detach().clone())
        self.register_buffer("start_mass", torch.as_tensor(start.body_mass, **f64))
        self.register_buffer("start_com", torch.as_tensor(start.body_com, **f64))
        self.register_buffer("start_inertia", torch.as_tensor(start.body_inertia, **f64))
        # the servo fields last: a robot without servos keeps the parameter order it had before they existed
        self.ref["deadband"] = np.full(n, DEADBAND_REF)
        self.register_buffer("ref_deadband", torch.as_tensor(self.ref["deadband"], **f64))
        self.register_parameter("u_deadband", torch.nn.Parameter(torch.as_tensor(start.deadband / DEADBAND_REF, **f64),
                                                                 "deadband" in self.fit))
        for f in ("noload_speed", "goal_accel"):
            self.register_buffer(f"start_{f}", torch.as_tensor(getattr(start, f), **f64))
            self.register_parameter(f"u_{f}", torch.nn.Parameter(torch.zeros(n, **f64), f in self.fit))
        # the startup torque in units of the friction's reference (both are torques a hold must overcome)
        self.ref["startup_torque"] = 0.05 * eff_ref
        self.register_buffer("ref_startup_torque", torch.as_tensor(self.ref["startup_torque"], **f64))
        self.register_parameter("u_startup_torque", torch.nn.Parameter(
            torch.as_tensor(start.startup_torque / self.ref["startup_torque"], **f64), "startup_torque" in self.fit))
        self.ref["stiction"] = 0.05 * eff_ref  # the friction's reference: the two add up at rest
        self.register_buffer("ref_stiction", torch.as_tensor(self.ref["stiction"], **f64))
        self.register_parameter("u_stiction", torch.nn.Parameter(
            torch.as_tensor(start.stiction / self.ref["stiction"], **f64), "stiction" in self.fit))
        for f in ("backlash", "encoder_offset"):  # angles in the dead band's unit
            self.ref[f] = np.full(n, DEADBAND_REF)
            self.register_buffer(f"ref_{f}", torch.as_tensor(self.ref[f], **f64))
            self.register_parameter(f"u_{f}", torch.nn.Parameter(
                torch.as_tensor(getattr(start, f) / DEADBAND_REF, **f64), f in self.fit))
        self.ref["load_friction"] = np.full(n, LOAD_FRICTION_REF)
        self.register_buffer("ref_load_friction", torch.as_tensor(self.ref["load_friction"], **f64))
        self.register_parameter("u_load_friction", torch.nn.Parameter(
            torch.as_tensor(start.load_friction / LOAD_FRICTION_REF, **f64), "load_friction" in self.fit))

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):
        """As torch's; a state saved before the startup torque, the stiction, the backlash, the encoder offset or the
        load friction existed takes this module's (the start's)."""
        state_dict = dict(state_dict)
        for k in (f"{p}_{f}" for f in ("startup_torque", "stiction", "backlash", "encoder_offset", "load_friction")
                  for p in ("u", "ref")):
            state_dict.setdefault(k, getattr(self, k).detach().clone())
        return super().load_state_dict(state_dict, strict=strict, assign=assign)

    def forward(self) -> dict[str, torch.Tensor]:
        """Current values, float64 tensors named as :class:`PhysicalParams` fields (delay in seconds)."""
        out = {f: getattr(self, f"start_{f}") * torch.exp(getattr(self, f"u_{f}")) for f in _LOG_FIELDS}
        for f in self.ref:
            out[f] = getattr(self, f"ref_{f}") * (self._u_delay() if f == "delay" else getattr(self, f"u_{f}"))
        nm = len(self.moving)
        u = torch.diag_embed(torch.exp(self.u_body_logdiag))
        u = u.index_put((torch.arange(nm, device=u.device)[:, None].expand(nm, 6), self.triu[0].expand(nm, 6),
                         self.triu[1].expand(nm, 6)), self.u_body_off)
        m, c, inertia = from_pseudo_inertia(u @ u.transpose(-1, -2))
        out["body_mass"] = self.start_mass.index_put((self.moving,), m)
        out["body_com"] = self.start_com.index_put((self.moving,), c)
        out["body_inertia"] = self.start_inertia.index_put((self.moving,), inertia)
        return out

    @torch.no_grad()
    def project(self) -> None:
        """Keep the linear fields' coordinates >= 0 but the encoder offset's (call after each optimiser step); the
        effort limit gets a
        positive floor (a drive with no torque is not physical), 0.05 of the robot's limit or the ``effort_floor``
        asked for."""
        for f in self.ref:
            u = getattr(self, f"u_{f}")
            if f == "encoder_offset":
                continue
            if f == "effort":
                floor = self.effort_floor_u()  # a scalar floor as a clamp: no host tensor copied in a capture
                u.copy_(u.clamp(min=floor) if isinstance(floor, float) else torch.maximum(u, floor))
            else:
                u.clamp_(min=0.0)

    def effort_floor_u(self) -> torch.Tensor | float:
        """The least effort-limit coordinate :meth:`project` keeps: ``effort_floor`` per joint, else 0.05."""
        return 0.05 if self.effort_floor is None else self.effort_floor

    @torch.no_grad()
    def assign(self, field: str, value, keep=None) -> None:
        """Set a joint field (:data:`JOINT_FIELDS`, :data:`SERVO_FIELDS`) to ``value`` (n,) [SI]: the inverse of
        :meth:`forward` on its coordinates. Joints where ``keep`` (n,) bool is true, where ``value`` is not finite, or
        where a log-scale field starts at 0, keep their value."""
        u = getattr(self, f"u_{field}")
        v = torch.as_tensor(np.asarray(value, dtype=np.float64), device=u.device)
        hold = ~torch.isfinite(v)
        if field in self.ref:  # linear: value = ref * u
            new = v / getattr(self, f"ref_{field}")
        else:  # exp-parametrised (gains, armature, servo speeds): value = start * exp(u); a start of 0 stays 0
            start = getattr(self, f"start_{field}")
            new = torch.log(v / start)
            hold |= start == 0
        if keep is not None:
            hold |= torch.as_tensor(np.asarray(keep, dtype=bool), device=u.device)
        u.copy_(torch.where(hold, u, new))

    def delay_steps(self) -> torch.Tensor:
        """The delay in sample periods, (n,) float64 (what :class:`~wresdyn.sim.bank.TrajectoryBank` takes)."""
        return self.ref_delay * self._u_delay() / self.dt

    def _u_delay(self) -> torch.Tensor:
        """The delay's coordinates, (n,): the shared one on every joint with ``shared_delay``."""
        return self.u_delay.mean().expand_as(self.u_delay) if self.shared_delay else self.u_delay

    def goal_accel_steps(self) -> torch.Tensor:
        """The servo goal acceleration in rad per sample period², (n,) float64 (what
        :meth:`~wresdyn.sim.bank.TrajectoryBank.set_goal_accel` takes; 0: no profile)."""
        return self.start_goal_accel * torch.exp(self.u_goal_accel) * self.dt ** 2

    def values(self) -> PhysicalParams:
        """The current values as :class:`PhysicalParams` (numpy)."""
        with torch.no_grad():
            v = {k: t.detach().cpu().numpy().copy() for k, t in self().items()}
        return PhysicalParams(list(self.robot.joint_names), list(self.robot.body_names), **v)

    def prior(self) -> torch.Tensor:
        """Squared distance of the coordinates from the start, in their own units (a weak prior for what the
        data cannot tell apart, e.g. the mass of a link against its centre of mass along the joint axis)."""
        terms = [getattr(self, f"u_{f}") ** 2 for f in _LOG_FIELDS if f in self.fit]
        if "bodies" in self.fit:
            terms.append((self.u_body_logdiag - self.u0_body_logdiag) ** 2)
            scale = torch.exp(self.u0_body_logdiag).amax(-1, keepdim=True)  # off-diagonals relative to the factor
            terms.append(((self.u_body_off - self.u0_body_off) / scale) ** 2)
        if not terms:
            return torch.zeros((), dtype=torch.float64, device=self.ref_delay.device)
        return sum(t.sum() for t in terms)


def _moves(robot, b: int) -> bool:
    """Whether body ``b`` moves: some joint on its path to the world is not fixed."""
    while b >= 0:
        if robot.joint_type[b] != "fixed":
            return True
        b = int(robot.body_parent[b])
    return False
