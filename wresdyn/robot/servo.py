"""Smart-servo drives: joints whose actuator closes its own position loop (Feetech STS, Dynamixel-style servos).

A servo joint is selected per joint in the gains config (``drive = "servo"``, :func:`read_servo`) and replaces the
PD drive of eq. (1) by the servo law, in SI units, per joint (the same law in
:mod:`wresdyn.sim.solver_replay` and in the MuJoCo "real" robot, :func:`servo_torque`)::

    e    = q*_s - (q + o)                             position error against the profiled goal [rad]
    e_m  = e - clamp(e, -beta, beta)                  the motor's error across the backlash's play [rad]
    e_b  = e_m - clamp(e_m, -b, b)                    dead band of half-width b [rad] (soft threshold)
    u    = clamp(kp e_b + u0 clamp(e_b / r, -1, 1)    duty in torque units [N*m], U = effort (stall torque),
                 + kd (qd* - qd), -U, U)              u0 startup torque over a ramp of r = one encoder tick
    tau  = g clamp(u - (U / w0) qd, -U, U)            DC motor torque-speed line, no-load speed w0 [rad/s]
    g    = min(|e_m| / r, 1) if beta > 0 else 1      the gear train's contact (0 inside the play)

Inside the band the position loop is off (the joint rests where friction, gravity and its history leave it, so
the hysteresis lives in the mechanical state) and the soft threshold keeps a gradient in ``b``. Outside it the
servo drives with at least ``u0`` (Feetech's "minimum startup force"), reached within one tick of the band's edge
(a continuous ramp, so the law stays differentiable); ``u0 = 0`` leaves it out. ``w0 = 0`` leaves the torque-speed
line out. Gear friction is the joint's ``friction`` (dry) and ``damping`` (viscous), with a static friction above
the dry one while the joint rests (a Stribeck curve, linear in the speed, over the joint's previous velocity)::

    mu(qd) = friction + stiction max(1 - |qd| / v_s, 0)   the dry friction's bound [N*m], v_s = STICTION_SPEED
             + eta |tau|                                  load friction, tau the drive torque of the step

so a joint at rest breaks away at ``friction + stiction`` and slides against ``friction`` once it moves faster than
``v_s``; ``stiction = 0`` leaves it out. ``eta`` (``load_friction``, dimensionless) is the gear train's friction
that grows with the torque it carries (a spur gear's mesh losses are a share of the tooth load, which is why BAM
models the STS3215's friction as load-dependent: Duclusaud & Passault 2025): a servo holding against gravity then
rests anywhere within a band that widens with the load; ``eta = 0`` leaves it out.

Two optional fields (0 by default, the law then exactly the one without them) describe the transmission and the
encoder:

- ``encoder_offset`` o [rad] (signed): the servo's encoder reads the joint's position (the recorded q and the
  model's coordinate) plus o, so its loop holds every goal o short (a per-unit calibration error of the zero).
- ``backlash`` beta [rad]: the half-width of the gear train's play between motor and link. The motor's own
  inertia is small against the link's, so the motor is taken as quasi-static: inside the play (|e| <= beta) it has
  reached the goal and transmits nothing (g = 0: the link swings freely, no loop, no back-EMF damping); once the
  link is further than beta from the goal the motor presses on it from beta away, so the drive acts on the error
  ``e_m`` the motor sees (and the dead band on that). The contact ``g`` ramps in over one encoder tick, which keeps
  the law continuous and its gradient in beta (through ``e_m``) defined. The firmware dead band differs: inside it
  the loop is off but the motor stays in mesh, damping the link through its back-EMF. IsaacLab's backlash actuator
  is a dead zone on the position error (this law's ``e_m``); its ``DriveBam`` adds a play hinge with its own state,
  which a stateless law of one step does not have, hence the quasi-static motor.

The goal q*_s is the command after the servo's acceleration profile (:class:`GoalProfile`): the internal goal
moves toward the command with at most ``a_max`` [rad/s²], braking in time to stop on it (``a_max = 0``: the
command itself, Feetech's "acceleration 0"). It acts on the command path, after the delay.
"""

from __future__ import annotations

import fnmatch
import math
from dataclasses import dataclass

import numpy as np

from ..errors import RobotError

__all__ = ["SERVO_KEYS", "STARTUP_RAMP", "STICTION_SPEED", "STS3215", "GoalProfile", "ServoDrives", "attach_servo",
           "friction_bound", "play", "profile_step", "read_servo", "servo_torque"]

SERVO_KEYS = ("drive", "deadband", "noload_speed", "goal_accel", "startup_torque", "stiction", "backlash",
              "encoder_offset", "load_friction")
"""Keys of a gains config's ``[[joint]]`` table that set the drive law (the others are
:func:`wresdyn.robot.description.apply_overrides`')."""

_TICK = 2.0 * math.pi / 4096.0
"""One encoder tick of a 12-bit servo [rad]."""
STARTUP_RAMP = _TICK
"""Error beyond the dead band over which the startup torque ramps in [rad]: one tick, the firmware's resolution."""
STICTION_SPEED = 0.05
"""Speed below which the static friction sets in [rad/s], linearly to its full value at rest: above the creep of
the replay's soft dry friction under a load below its bound (``tau R / b``: 0.007-0.011 rad/s for 0.3 N*m on the
SO-101's joints), below the arm's moves (0.3-3 rad/s)."""


@dataclass(frozen=True)
class _Prior:
    kp: float
    kd: float
    effort: float
    deadband: float
    noload_speed: float
    goal_accel: float


STS3215 = _Prior(
    # duty = firmware P * error_gain * e [rad]; error_gain = 0.166 /rad per unit of P, measured with an oscilloscope
    # by BAM (Duclusaud & Passault 2025, bam/feetech/sts3215.py); LeRobot's SO-101 follower writes P_Coefficient 16;
    # full duty is the stall torque: kp = 16 * 0.166 * 1.91 = 5.07 N*m/rad (the arm's measured 4.6-12.3)
    kp=16 * 0.166 * 1.91,
    # D_Coefficient 32 on the error's change per firmware cycle, taken as 1 ms with P's scale: a guess (no
    # published mapping), small against the motor's own back-EMF damping 1.91 / 5.45 = 0.35 N*m*s/rad
    kd=32 * 0.166 * 1.91 * 1e-3,
    # 7.4 V STS3215 stall torque 19.5 kg*cm (Feetech data sheet; scenes/so101/mismatch.toml)
    effort=1.91,
    # the CW/CCW dead zone registers' default of one tick
    deadband=_TICK,
    # no-load speed 0.192 s / 60 deg (52 rpm) at 7.4 V: the 19.5 kg*cm STS3215's data sheet (DFRobot SER0069 /
    # Feetech; scenes/so101/README.md); 0.222 s / 60 deg is the 12 V, 30 kg*cm C018's
    noload_speed=(math.pi / 3.0) / 0.192,
    # Acceleration 254 (LeRobot's follower) in units of 100 ticks/s^2 (Feetech's control table, address 41)
    goal_accel=254 * 100 * _TICK,
)
"""Priors of the 7.4 V Feetech STS3215 as LeRobot configures it on the SO-101 follower (sources inline)."""


@dataclass(frozen=True)
class ServoDrives:
    """Which joints are servos and their servo-only parameters, per actuated joint in DoF order."""

    mask: np.ndarray
    """True where the joint's drive is a servo, shape (n_dof,)."""
    deadband: np.ndarray
    """Dead band half-width b [rad], shape (n_dof,)."""
    noload_speed: np.ndarray
    """Motor no-load speed w0 [rad/s] (0: no torque-speed line), shape (n_dof,)."""
    goal_accel: np.ndarray
    """Goal acceleration limit a_max [rad/s²] (0: no profile), shape (n_dof,)."""
    startup_torque: np.ndarray
    """Least drive torque u0 outside the dead band [N*m] (0: none), shape (n_dof,)."""
    stiction: np.ndarray
    """Static friction above the dry friction at rest [N*m] (0: none), shape (n_dof,)."""
    backlash: np.ndarray
    """Half-width beta of the gear train's play between motor and link [rad] (0: none), shape (n_dof,)."""
    encoder_offset: np.ndarray
    """Encoder zero offset o [rad], signed: the servo's loop sees q + o (0: none), shape (n_dof,)."""
    load_friction: np.ndarray
    """Gear friction per unit of drive torque eta [-] (0: none), shape (n_dof,)."""


def read_servo(config: dict | None, joint_names, effort, where: str = "gains config") -> ServoDrives | None:
    """The servo drives a gains config selects (``drive = "servo"`` in ``[[joint]]`` tables, later ones winning),
    or ``None`` when it selects none.

    ``deadband``, ``backlash``, ``encoder_offset`` (signed) [rad], ``noload_speed`` [rad/s], ``goal_accel``
    [rad/s²], ``startup_torque`` and ``stiction`` [N*m], ``load_friction`` [-] may be set in any entry; a servo
    joint not given one takes zero (no band, no torque-speed line, no profile). A servo needs a finite effort
    limit (its stall torque).

    Raises:
        RobotError: an unknown drive name, a negative value, or a servo without an effort limit.
    """
    if not config:
        return None
    n = len(joint_names)
    drive = np.zeros(n, dtype=bool)
    values = {k: np.zeros(n) for k in SERVO_KEYS[1:]}
    for e in config.get("joint", []):
        if not isinstance(e, dict) or not any(k in e for k in SERVO_KEYS):
            continue
        hits = np.array([fnmatch.fnmatchcase(name, str(e.get("match", ""))) for name in joint_names], dtype=bool)
        if "drive" in e:
            if e["drive"] not in ("servo", "pd"):
                raise RobotError(f"{where}: drive = {e['drive']!r} for {e.get('match')!r}: choose \"servo\" or \"pd\"")
            drive[hits] = e["drive"] == "servo"
        for k in SERVO_KEYS[1:]:
            if k in e:
                try:
                    v = float(e[k])
                except (TypeError, ValueError):
                    raise RobotError(f"{where}: {k} = {e[k]!r} for {e.get('match')!r} is not a number") from None
                if not (math.isfinite(v) and (v >= 0.0 or k == "encoder_offset")):
                    raise RobotError(f"{where}: {k} = {v} for {e.get('match')!r} must be finite and >= 0")
                values[k][hits] = v
    if not drive.any():
        return None
    bad = [name for name, s, f in zip(joint_names, drive, effort) if s and not np.isfinite(f)]
    if bad:
        raise RobotError(f"{where}: servo joint(s) {', '.join(bad[:4])} need an effort limit (the stall torque): "
                         "set effort = ... [N*m]")
    return ServoDrives(drive, *(np.where(drive, values[k], 0.0) for k in SERVO_KEYS[1:]))


def attach_servo(model, servo: ServoDrives, qd_index, num_worlds: int) -> None:
    """Give a finalized Newton model the servo arrays :class:`~wresdyn.sim.solver_replay.SolverReplay` reads, per
    DoF of every world (Newton's flat layout, zeros on the DoFs of other joints): ``joint_servo`` (int32, 1 on a
    servo), ``joint_servo_deadband`` [rad], ``joint_servo_noload_speed`` [rad/s], ``joint_servo_startup_torque`` and
    ``joint_servo_stiction`` [N*m], ``joint_servo_backlash`` and ``joint_servo_encoder_offset`` [rad],
    ``joint_servo_load_friction`` [-] (float32, gradients as the model's)."""
    import warp as wp

    width = model.joint_dof_count // num_worlds
    idx = np.asarray(qd_index, dtype=np.int64)

    def per_dof(values, dtype):
        full = np.zeros((num_worlds, width))
        full[:, idx] = values
        return wp.array(full.reshape(-1).astype(dtype), device=model.device,
                        requires_grad=bool(model.requires_grad) and dtype == np.float32)

    model.joint_servo = per_dof(servo.mask.astype(float), np.int32)
    model.joint_servo_deadband = per_dof(servo.deadband, np.float32)
    model.joint_servo_noload_speed = per_dof(servo.noload_speed, np.float32)
    model.joint_servo_startup_torque = per_dof(servo.startup_torque, np.float32)
    model.joint_servo_stiction = per_dof(servo.stiction, np.float32)
    model.joint_servo_backlash = per_dof(servo.backlash, np.float32)
    model.joint_servo_encoder_offset = per_dof(servo.encoder_offset, np.float32)
    model.joint_servo_load_friction = per_dof(servo.load_friction, np.float32)


def servo_torque(q_goal, q, qd, kp, kd, deadband, effort, noload_speed, qd_goal=0.0, startup_torque=0.0,
                 backlash=0.0, encoder_offset=0.0):
    """The servo law of the module docstring (numpy, any broadcastable shapes): the drive torque [N*m]."""
    e_m, gate = play(q_goal - (q + encoder_offset), backlash)
    e_b = e_m - np.clip(e_m, -deadband, deadband)
    u = np.clip(kp * e_b + startup_torque * np.clip(e_b / STARTUP_RAMP, -1.0, 1.0) + kd * (qd_goal - qd), -effort,
                effort)
    emf = np.divide(effort, noload_speed, out=np.zeros(np.broadcast(effort, noload_speed).shape),
                    where=np.asarray(noload_speed) > 0)
    return gate * np.clip(u - emf * qd, -effort, effort)


def play(e, backlash):
    """The backlash of the module docstring (numpy, broadcastable): the motor's error ``e_m`` [rad] across the play
    of half-width ``backlash`` and the gear train's contact ``g`` in [0, 1] (1 where ``backlash`` is 0)."""
    e_m = e - np.clip(e, -backlash, backlash)
    return e_m, np.where(np.asarray(backlash) > 0, np.minimum(np.abs(e_m) / STARTUP_RAMP, 1.0), 1.0)


def friction_bound(qd, friction, stiction, load_friction=0.0, torque=0.0):
    """The dry friction's bound of the module docstring (numpy, broadcastable) at the previous velocity ``qd``
    [rad/s] and the step's drive torque ``torque`` [N*m]: ``friction + stiction max(1 - |qd| / v_s, 0) + eta |tau|``
    [N*m]."""
    return friction + stiction * np.maximum(1.0 - np.abs(qd) / STICTION_SPEED, 0.0) + load_friction * np.abs(torque)


def profile_step(xp, goal, pos, vel, accel):
    """One step of the goal profile in step units (``xp``: numpy or torch): the internal goal ``pos`` [rad] and its
    speed ``vel`` [rad/step] move toward the command ``goal`` with at most ``accel`` [rad/step²] > 0, at the speed
    that still stops on it (``sqrt(2 a |e|)``, and at most the whole distance in one step). Returns (pos, vel)."""
    e = goal - pos
    dist = xp.abs(e)
    # the floor keeps sqrt's derivative finite at e = 0, where the distance term is the smaller one anyway
    brake = xp.sqrt(xp.clip(2.0 * accel * dist, 1e-30, None))
    want = xp.sign(e) * xp.minimum(brake, dist)
    vel = vel + xp.clip(want - vel, -accel, accel)
    return pos + vel, vel


class GoalProfile:
    """The servo's internal goal for commands arriving one physics step apart (numpy), for the MuJoCo robot:
    :func:`profile_step` with ``a_max dt²`` on the joints with ``a_max > 0``; the others follow the command."""

    def __init__(self, goal_accel: np.ndarray, dt: float, start: np.ndarray) -> None:
        self.on = np.asarray(goal_accel, dtype=np.float64) > 0
        self.accel = np.where(self.on, goal_accel, 1.0) * dt * dt
        self.pos, self.vel = np.array(start, dtype=np.float64), np.zeros(len(self.on))

    def __call__(self, command: np.ndarray) -> np.ndarray:
        pos, vel = profile_step(np, command, self.pos, self.vel, self.accel)
        self.pos, self.vel = np.where(self.on, pos, command), np.where(self.on, vel, 0.0)
        return self.pos.copy()
