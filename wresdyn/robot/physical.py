"""Physical parameters of one robot as fitted quantities: per joint and per link, SI units, numpy float64.

:class:`PhysicalParams` is what the grey-box identification fits, what the simulated "real" robot reports as its
truth (:meth:`wresdyn.data.real_robot.RealRobot.physics`) and what a calibrated robot carries, read and written as
JSON (never a pickle). It needs neither torch nor Newton, so data collection reads it without them; the table of
fields, units and the Newton model arrays each one sets, and the torch module that fits them, are in
:mod:`wresdyn.sim.physics`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np

from ..errors import WresdynError

__all__ = ["JOINT_FIELDS", "SERVO_FIELDS", "BODY_FIELDS", "PhysicalParams", "PhysicsError"]

JOINT_FIELDS = ("kp", "kd", "armature", "damping", "friction", "effort", "delay")
"""Per-joint fields of :class:`PhysicalParams`, each (n_dof,)."""
SERVO_FIELDS = ("deadband", "noload_speed", "goal_accel", "startup_torque", "stiction", "backlash", "encoder_offset",
                "load_friction")
"""Per-joint fields of the servo drive law (:mod:`wresdyn.robot.servo`), each (n_dof,); read only on joints whose
drive is a servo, 0 elsewhere. Files written before they existed load with zeros."""
BODY_FIELDS = ("body_mass", "body_com", "body_inertia")
"""Per-body fields, (n_bodies,), (n_bodies, 3), (n_bodies, 3, 3)."""


class PhysicsError(WresdynError):
    """A parameter file that cannot be used; the message is one line naming the file."""


@dataclass
class PhysicalParams:
    """Physical parameters of one robot, SI units (the table in :mod:`wresdyn.sim.physics`). Arrays float64."""

    joint_names: list[str]
    body_names: list[str]
    kp: np.ndarray
    kd: np.ndarray
    armature: np.ndarray
    damping: np.ndarray
    friction: np.ndarray
    effort: np.ndarray
    """Effort limit [N·m]; ``inf`` = unlimited."""
    delay: np.ndarray
    """Actuator delay [s] of each joint's command."""
    body_mass: np.ndarray
    body_com: np.ndarray
    body_inertia: np.ndarray
    deadband: np.ndarray | None = None
    """Servo dead band half-width [rad] (0: none); ``None`` on construction means zeros."""
    noload_speed: np.ndarray | None = None
    """Servo motor no-load speed [rad/s] (0: no torque-speed line)."""
    goal_accel: np.ndarray | None = None
    """Servo goal acceleration limit [rad/s²] (0: no goal profile)."""
    startup_torque: np.ndarray | None = None
    """Servo's least drive torque outside its dead band [N·m] (0: none)."""
    stiction: np.ndarray | None = None
    """Servo joint's static friction above ``friction`` at rest [N·m] (0: none)."""
    backlash: np.ndarray | None = None
    """Servo gear train's play, half-width [rad] (0: none)."""
    encoder_offset: np.ndarray | None = None
    """Servo encoder's zero offset [rad], signed: its loop sees q + offset (0: none)."""
    load_friction: np.ndarray | None = None
    """Servo gear friction per unit of drive torque [-] (0: none)."""

    def __post_init__(self) -> None:
        for f in SERVO_FIELDS:
            if getattr(self, f) is None:
                setattr(self, f, np.zeros(len(self.joint_names)))

    @classmethod
    def nominal(cls, robot) -> "PhysicalParams":
        """The robot file's values (no delay)."""
        n = robot.n_dof
        servo = getattr(robot, "servo", None)
        return cls(list(robot.joint_names), list(robot.body_names), *(np.array(getattr(robot, f), dtype=np.float64)
                   for f in ("kp", "kd", "armature", "damping", "friction", "effort")), np.zeros(n),
                   np.array(robot.body_mass, dtype=np.float64), np.array(robot.body_com, dtype=np.float64),
                   np.array(robot.body_inertia, dtype=np.float64),
                   **({} if servo is None else {f: np.array(getattr(servo, f), dtype=np.float64) for f in SERVO_FIELDS}))

    @classmethod
    def mean(cls, params) -> "PhysicalParams":
        """The field-by-field mean of parameters of one robot (an ensemble of identifications, one model). It stays
        physical: every field's admissible set is convex (signs; a body's inertia about its centre of mass, whose
        triangle inequalities are linear in it)."""
        params = list(params)
        first = params[0]
        for p in params[1:]:
            if (p.joint_names, p.body_names) != (first.joint_names, first.body_names):
                raise PhysicsError("parameters of different robots cannot be averaged")
        return cls(list(first.joint_names), list(first.body_names),
                   **{f: np.mean([getattr(p, f) for p in params], axis=0)
                      for f in (*JOINT_FIELDS, *BODY_FIELDS, *SERVO_FIELDS)})

    def copy(self) -> "PhysicalParams":
        return PhysicalParams(**{f.name: (list(v) if isinstance(v := getattr(self, f.name), list) else v.copy())
                                 for f in fields(self)})

    def check(self, robot, where: str = "parameters") -> None:
        """Raise :class:`PhysicsError` unless these parameters describe ``robot`` (names, shapes, signs)."""
        if list(self.joint_names) != list(robot.joint_names):
            raise PhysicsError(f"{where}: joint names {self.joint_names[:3]}... do not match the robot's "
                               f"{list(robot.joint_names)[:3]}... ({len(self.joint_names)} vs {robot.n_dof} joints)")
        if list(self.body_names) != list(robot.body_names):
            raise PhysicsError(f"{where}: body names do not match the robot's ({len(self.body_names)} vs "
                               f"{robot.n_bodies} bodies)")
        n, nb = robot.n_dof, robot.n_bodies
        want = {**{f: (n,) for f in (*JOINT_FIELDS, *SERVO_FIELDS)}, "body_mass": (nb,), "body_com": (nb, 3), "body_inertia": (nb, 3, 3)}
        for f, shape in want.items():
            a = getattr(self, f)
            if a.shape != shape:
                raise PhysicsError(f"{where}: {f} has shape {a.shape}, expected {shape}")
            if np.isnan(a).any() or (f != "effort" and not np.isfinite(a).all()):
                raise PhysicsError(f"{where}: {f} is not finite")
            if f in ("kp", "kd", "armature", "damping", "friction", "effort", "delay", "body_mass", *SERVO_FIELDS) \
                    and f != "encoder_offset" and (a < 0).any():
                raise PhysicsError(f"{where}: {f} must be >= 0")

    # ------------------------------------------------------------------------------------------------ JSON
    def to_json(self) -> dict:
        d = {"format": "wresdyn.physics/1", "joint_names": self.joint_names, "body_names": self.body_names}
        for f in (*JOINT_FIELDS, *BODY_FIELDS, *SERVO_FIELDS):
            a = getattr(self, f)
            d[f] = np.where(np.isfinite(a), a, -1.0).tolist() if f == "effort" else a.tolist()
        return d

    def save(self, path: str | Path) -> None:
        """Write JSON atomically (``effort`` −1 = unlimited)."""
        path = Path(path)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(self.to_json(), indent=1))
        tmp.replace(path)

    @classmethod
    def load(cls, path: str | Path, robot=None) -> "PhysicalParams":
        """Read a file written by :meth:`save`; with ``robot``, check it describes that robot."""
        path = Path(path)
        if not path.is_file():
            raise PhysicsError(f"{path}: parameter file not found")
        try:
            d = json.loads(path.read_text())
            if d.get("format") != "wresdyn.physics/1":
                raise PhysicsError(f"{path}: not a wresdyn physics file (format {d.get('format')!r})")
            arrays = {f: np.asarray(d[f], dtype=np.float64) for f in (*JOINT_FIELDS, *BODY_FIELDS)}
            arrays.update({f: np.asarray(d[f], dtype=np.float64) for f in SERVO_FIELDS if f in d})
        except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError, ValueError) as e:
            if isinstance(e, PhysicsError):
                raise
            raise PhysicsError(f"{path}: malformed physics file ({type(e).__name__}: {e})") from None
        arrays["effort"] = np.where(arrays["effort"] < 0, np.inf, arrays["effort"])
        p = cls(list(d["joint_names"]), list(d["body_names"]), **arrays)
        if robot is not None:
            p.check(robot, str(path))
        return p
