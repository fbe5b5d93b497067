"""A smart-servo drive for ``newton.actuators``: the part of the servo law Newton's stock components lack.

``wresdyn export`` copies this file next to the layers of a robot with servo drives; it imports newton, warp and
pxr only (nothing of wresdyn). A servo joint's ``NewtonActuator`` prim applies ``WresdynServoControlAPI`` (this
drive) with Newton's own ``NewtonActuatorDelayAPI`` (the command delay) and ``NewtonDCMotorClampingAPI`` (the DC
motor's torque–speed line, or ``NewtonMaxEffortClampingAPI`` without one). Per actuator step of ``dt`` [s], in SI
units::

    g, v  <- profile(g, v, q*)                       internal goal g [rad] toward the delayed command q* with at
                                                     most a_max [rad/s²], braking in time to stop on it
    e     =  g - (q + o)                              position error [rad], o the encoder's zero offset
    e_m   =  e - clamp(e, -beta, beta)                the motor's error across the gear play beta [rad]
    e_b   =  e_m - clamp(e_m, -b, b)                  dead band of half-width b [rad] (soft threshold)
    x     =  c (kp e_b + u0 clamp(e_b / tick, -1, 1)   this drive's output [N m], c = min(|e_m| / tick, 1)
              + kd (qd* - qd) - (U / w0) qd)         the gear contact where beta > 0 (else 1), u0 the startup
                                                     torque ramped in over one encoder tick past the dead band
    tau   =  clamp(x, -U (1 + qd / w0), U (1 - qd / w0)) within [-U, U]      ClampingDCMotor(U, w0, U)

which is the servo law ``tau = clamp(clamp(kp e_b + u0 clamp(e_b / tick, -1, 1) + kd (qd* - qd), -U, U)
- (U / w0) qd, -U, U)`` (a duty clamped to the stall torque U, minus the back-EMF of a motor whose torque falls
to zero at the no-load speed w0): subtracting ``(U / w0) qd`` before the DC motor's clamp shifts its bounds by the
same amount. With a backlash the contact scales the drive before the clamp (wresdyn's law scales the clamped
torque): they differ while the drive saturates within one encoder tick of the play's edge, and inside the play at a
speed past w0, where the DC motor's clamp keeps a torque (its bounds exclude 0 there) that the law's contact
zeroes.

USD attributes of ``WresdynServoControlAPI`` (Newton's parser reads an actuator schema's attributes from the
``newton:`` namespace only, so they live there): ``newton:kp`` [N m/rad], ``newton:kd`` [N m s/rad],
``newton:servoDeadband`` b [rad], ``newton:servoGoalAccel`` a_max [rad/s²] (0: the goal is the command) and
``newton:servoBackEmf`` U / w0 [N m s/rad] (0: no torque–speed line), ``newton:servoBacklash`` beta [rad] and
``newton:servoEncoderOffset`` o [rad] (signed; both 0: none), ``newton:servoStartupTorque`` u0 [N m] (0: none).

Use it in a plain Newton script (before the first USD stage is opened: USD builds its schema registry once)::

    import servo_actuator                       # this file, from the export folder
    servo_actuator.register()                   # the USD schema + newton.actuators.register_actuator_component
    builder = newton.ModelBuilder()
    builder.add_usd("export/actuated.usda")     # servo joints get this drive, PD joints DrivePD

The drive keeps the goal profile's state (goal, its speed, whether it started) in ``Actuator.State``: the goal
starts at rest on the first command an actuator sees; reset the state (``state.reset()``) at a new start.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import warp as wp
from newton.actuators import ComponentKind, DriveBase, register_actuator_component

__all__ = ["SCHEMA", "DriveServo", "register"]

SCHEMA = "WresdynServoControlAPI"
"""The applied API schema a servo's ``NewtonActuator`` prim carries."""
SCHEMA_DIR = "wresdyn_servo_schema"
"""Folder next to this file (in the package and in an export) of the codeless USD schema plugin: plugInfo.json and
generatedSchema.usda, whose attributes are :data:`_ATTRS`'s."""

_ATTRS = {  # USD name: (kwarg, doc in the schema)
    "newton:kp": ("kp", "Position-loop gain on the dead-banded error [N m/rad]"),
    "newton:kd": ("kd", "Velocity gain [N m s/rad]"),
    "newton:servoDeadband": ("servo_deadband", "Dead band half-width b [rad]"),
    "newton:servoGoalAccel": ("servo_goal_accel",
                              "Goal acceleration limit a_max [rad/s^2]; 0: the goal is the command"),
    "newton:servoBackEmf": ("servo_back_emf", "Back-EMF damping U / w0 [N m s/rad]; 0: no torque-speed line"),
    "newton:servoBacklash": ("servo_backlash", "Gear play half-width beta [rad]; 0: none"),
    "newton:servoEncoderOffset": ("servo_encoder_offset", "Encoder zero offset o [rad], signed: the loop sees q + o"),
    "newton:servoStartupTorque": ("servo_startup_torque", "Startup torque u0 [N m], ramped in over one encoder "
                                  "tick past the dead band; 0: none"),
}
_TICK = wp.constant(2.0 * math.pi / 4096.0)
"""One encoder tick of a 12-bit servo [rad]: the ramp over which the gear contact sets in past the play and the
startup torque past the dead band."""


def register() -> None:
    """Register the USD schema (the plugin folder next to this file) and the drive with Newton's actuator parser.
    Call it before the first USD stage of the process is opened.

    Raises:
        RuntimeError: the plugin folder is missing, or USD's schema registry was built before the schema was
            registered, so Newton's importer would not see it (import and register earlier, or put the plugin
            folder on ``PXR_PLUGINPATH_NAME``).
    """
    from pxr import Plug, Usd

    folder = Path(__file__).resolve().parent / SCHEMA_DIR
    if not (folder / "plugInfo.json").is_file():
        raise RuntimeError(f"{folder}: the schema plugin of {SCHEMA} is missing (it ships next to this file)")
    Plug.Registry().RegisterPlugins([str(folder)])
    if Usd.SchemaRegistry().FindAppliedAPIPrimDefinition(SCHEMA) is None:
        raise RuntimeError(f"{SCHEMA}: USD's schema registry was built before the schema was registered; call "
                           "servo_actuator.register() before opening any USD stage, or set PXR_PLUGINPATH_NAME to "
                           f"{folder}")
    register_actuator_component(SCHEMA, DriveServo, ComponentKind.DRIVE)


@wp.kernel
def _servo_kernel(
    current_pos: wp.array[float],
    current_vel: wp.array[float],
    target_pos: wp.array[float],
    target_vel: wp.array[float],
    pos_indices: wp.array[wp.uint32],
    vel_indices: wp.array[wp.uint32],
    target_pos_indices: wp.array[wp.uint32],
    target_vel_indices: wp.array[wp.uint32],
    kp: wp.array[float],
    kd: wp.array[float],
    deadband: wp.array[float],
    goal_accel: wp.array[float],
    back_emf: wp.array[float],
    backlash: wp.array[float],
    encoder_offset: wp.array[float],
    startup: wp.array[float],
    goal_in: wp.array[float],
    goal_vel_in: wp.array[float],
    started_in: wp.array[wp.int32],
    dt: float,
    efforts: wp.array[float],
    goal_out: wp.array[float],
    goal_vel_out: wp.array[float],
):
    i = wp.tid()
    cmd = target_pos[target_pos_indices[i]]
    goal = cmd
    speed = float(0.0)
    a = goal_accel[i] * dt * dt  # [rad/step^2]
    if a > 0.0:
        pos = goal_in[i]
        vel = goal_vel_in[i]
        if started_in[i] == 0:  # at rest on the first command
            pos = cmd
            vel = float(0.0)
        e = cmd - pos
        dist = wp.abs(e)
        brake = wp.sqrt(wp.max(2.0 * a * dist, 1e-30))
        want = wp.sign(e) * wp.min(brake, dist)
        if e == 0.0:  # on the goal: no push (wp.sign(0) is 1, numpy's 0)
            want = float(0.0)
        vel = vel + wp.clamp(want - vel, -a, a)
        goal = pos + vel
        speed = vel
    goal_out[i] = goal
    goal_vel_out[i] = speed

    qd = current_vel[vel_indices[i]]
    err = goal - (current_pos[pos_indices[i]] + encoder_offset[i])
    err_m = err - wp.clamp(err, -backlash[i], backlash[i])
    contact = float(1.0)
    if backlash[i] > 0.0:
        contact = wp.min(wp.abs(err_m) / _TICK, 1.0)
    err_b = err_m - wp.clamp(err_m, -deadband[i], deadband[i])
    kick = startup[i] * wp.clamp(err_b / _TICK, -1.0, 1.0)
    efforts[i] = contact * (kp[i] * err_b + kick + kd[i] * (target_vel[target_vel_indices[i]] - qd) - back_emf[i] * qd)


@wp.kernel
def _mark_started(started: wp.array[wp.int32]):
    started[wp.tid()] = 1


@wp.kernel
def _masked_reset(goal: wp.array[float], goal_vel: wp.array[float], started: wp.array[wp.int32],
                  mask: wp.array[wp.bool]):
    i = wp.tid()
    if mask[i]:
        goal[i] = 0.0
        goal_vel[i] = 0.0
        started[i] = 0


class DriveServo(DriveBase):
    """Smart-servo drive (module docstring): dead band, startup torque and goal profile on a PD law with back-EMF
    damping; pair it with ``ClampingDCMotor(U, w0, U)`` (or ``ClampingMaxEffort(U)``) for the stall torque and
    torque–speed line."""

    @dataclass
    class State(DriveBase.State):
        """The goal profile's state, per actuator."""

        goal: wp.array[float] | None = None
        """Internal goal [rad], shape (N,)."""
        goal_vel: wp.array[float] | None = None
        """Internal goal speed [rad/step], shape (N,)."""
        started: wp.array[wp.int32] | None = None
        """1 once the actuator has seen a command, shape (N,)."""

        def reset(self, mask: wp.array[wp.bool] | None = None) -> None:
            if mask is None:
                self.goal.zero_()
                self.goal_vel.zero_()
                self.started.zero_()
                return
            wp.launch(_masked_reset, dim=len(mask), inputs=[self.goal, self.goal_vel, self.started, mask],
                      device=self.goal.device)

    @classmethod
    def resolve_arguments(cls, args: dict[str, Any]) -> dict[str, Any]:
        out = {kw: float(args.get(kw, 0.0)) for kw, _ in _ATTRS.values()}
        bad = [k for k, v in out.items() if not (v >= 0.0 or (k == "servo_encoder_offset" and math.isfinite(v)))]
        if bad:
            raise ValueError(f"DriveServo: {', '.join(bad)} must be >= 0")
        return out

    def __init__(self, kp: wp.array[float], kd: wp.array[float], servo_deadband: wp.array[float],
                 servo_goal_accel: wp.array[float], servo_back_emf: wp.array[float],
                 servo_backlash: wp.array[float] | None = None, servo_encoder_offset: wp.array[float] | None = None,
                 servo_startup_torque: wp.array[float] | None = None):
        """Per-actuator parameter arrays, shape (N,): kp [N m/rad], kd [N m s/rad], dead band [rad], goal
        acceleration [rad/s²], back-EMF damping [N m s/rad], backlash and encoder offset [rad], startup torque
        [N m] (default 0)."""
        zero = lambda: wp.zeros(kp.shape, dtype=kp.dtype, device=kp.device)  # noqa: E731
        servo_backlash = zero() if servo_backlash is None else servo_backlash
        servo_encoder_offset = zero() if servo_encoder_offset is None else servo_encoder_offset
        servo_startup_torque = zero() if servo_startup_torque is None else servo_startup_torque
        for a in (kd, servo_deadband, servo_goal_accel, servo_back_emf, servo_backlash, servo_encoder_offset,
                  servo_startup_torque):
            if a.shape != kp.shape:
                raise ValueError(f"DriveServo: parameter shapes differ ({a.shape} and {kp.shape})")
        self.kp, self.kd = kp, kd
        self.deadband, self.goal_accel, self.back_emf = servo_deadband, servo_goal_accel, servo_back_emf
        self.backlash, self.encoder_offset = servo_backlash, servo_encoder_offset
        self.startup_torque = servo_startup_torque
        self._goal = self._goal_vel = None

    def finalize(self, device, num_actuators: int) -> None:
        self._goal = wp.zeros(num_actuators, dtype=wp.float32, device=device)
        self._goal_vel = wp.zeros(num_actuators, dtype=wp.float32, device=device)

    def is_stateful(self) -> bool:
        return True

    def is_graphable(self) -> bool:
        return True

    def state(self, num_actuators: int, device) -> DriveServo.State:
        return DriveServo.State(goal=wp.zeros(num_actuators, dtype=wp.float32, device=device),
                                goal_vel=wp.zeros(num_actuators, dtype=wp.float32, device=device),
                                started=wp.zeros(num_actuators, dtype=wp.int32, device=device))

    def compute(self, positions, velocities, target_pos, target_vel, feedforward, pos_indices, vel_indices,
                target_pos_indices, target_vel_indices, forces, state, dt, device=None, *, custom_inputs=None) -> None:
        wp.launch(_servo_kernel, dim=len(forces),
                  inputs=[positions, velocities, target_pos, target_vel, pos_indices, vel_indices, target_pos_indices,
                          target_vel_indices, self.kp, self.kd, self.deadband, self.goal_accel, self.back_emf,
                          self.backlash, self.encoder_offset, self.startup_torque, state.goal, state.goal_vel,
                          state.started, float(dt)],
                  outputs=[forces, self._goal, self._goal_vel], device=device)

    def update_state(self, current_state: DriveServo.State, next_state: DriveServo.State) -> None:
        wp.copy(next_state.goal, self._goal)
        wp.copy(next_state.goal_vel, self._goal_vel)
        wp.launch(_mark_started, dim=len(next_state.started), inputs=[next_state.started],
                  device=next_state.started.device)
