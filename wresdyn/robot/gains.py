"""The gains config: per-joint overrides of a robot file's drive and joint parameters (PD gains, effort limit,
armature, friction, damping, position limits) by joint-name pattern, read from TOML and applied to the Newton
builder before the robot is described (:func:`~wresdyn.robot.description.load_robot`)."""

from __future__ import annotations

import copy
import fnmatch
from pathlib import Path

import tomllib

from ..errors import RobotError
from .file_import import short_label
from .servo import SERVO_KEYS

__all__ = ["read_gains", "apply_overrides"]

_OVERRIDE_FIELDS = ("kp", "kd", "effort", "armature", "friction", "damping", "lower", "upper")


def read_gains(gains: str | Path | dict) -> tuple[dict, str | None]:
    """A gains config as ``(parsed dict, file path or None)``: a TOML file is read, a dict is copied.

    Raises:
        RobotError: the file is missing or not TOML.
    """
    if isinstance(gains, dict):
        return copy.deepcopy(gains), None
    gp = Path(gains)
    if not gp.is_file():
        raise RobotError(f"{gp}: gains config not found")
    try:
        return tomllib.loads(gp.read_text()), str(gains)
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise RobotError(f"{gp}: malformed TOML: {e}") from None


def apply_overrides(builder, gains: str | Path | dict, source: Path | None = None,
                    where: str | None = None) -> set[int]:
    """Override per-joint drive and joint parameters by joint-name pattern, in place.

    The config (TOML) holds ``[[joint]]`` tables applied in order, later ones winning::

        [[joint]]
        match = "*"            # fnmatch pattern on the joint name (last path element)
        kp = 100.0             # PD stiffness [N*m/rad]
        kd = 5.0               # PD damping [N*m*s/rad]
        [[joint]]
        match = "*_ankle_*"
        kp = 40.0
        effort = 50.0          # effort limit [N*m]
        armature = 0.01        # reflected rotor inertia [kg*m^2]

    Keys: ``kp kd effort armature friction damping lower upper``, and the servo drive's ``drive deadband
    noload_speed goal_accel startup_torque stiction`` (read by :func:`wresdyn.robot.servo.read_servo`, not here). A pattern
    that matches no joint is an error, so typos do not pass silently. An effort limit set here is taken as stated, even
    a huge one (see :meth:`~wresdyn.robot.description.Robot.check_effort`). Returns the DoF indices whose effort limit
    the config set.
    """
    if where is None:
        where = str(gains) if not isinstance(gains, dict) else "gains config"
    gains, _ = read_gains(gains)
    entries = gains.get("joint", [])
    if not isinstance(entries, list) or not entries:
        raise RobotError(f"{where}: expected one or more [[joint]] tables")
    attr = {"kp": "joint_target_ke", "kd": "joint_target_kd", "effort": "joint_effort_limit", "armature": "joint_armature",
            "friction": "joint_friction", "damping": "joint_damping", "lower": "joint_limit_lower", "upper": "joint_limit_upper"}
    labels = [short_label(label) for label in builder.joint_label]
    qd_start = list(builder.joint_qd_start)
    dof_dim = [int(a) + int(b) for a, b in builder.joint_dof_dim]
    effort_dofs: set[int] = set()
    for e in entries:
        if not isinstance(e, dict):
            raise RobotError(f"{where}: every [[joint]] entry must be a table")
        pattern = e.pop("match", None)
        if not isinstance(pattern, str):
            raise RobotError(f"{where}: every [[joint]] needs a match = \"pattern\" string")
        unknown = set(e) - set(_OVERRIDE_FIELDS) - set(SERVO_KEYS)
        if unknown:
            raise RobotError(f"{where}: unknown key(s) {sorted(unknown)} for match {pattern!r}; allowed: "
                             f"{list(_OVERRIDE_FIELDS) + list(SERVO_KEYS)}")
        hits = [j for j, n in enumerate(labels) if fnmatch.fnmatchcase(n, pattern) and dof_dim[j] == 1]
        if not hits:
            raise RobotError(f"{where}: pattern {pattern!r} matches no 1-DoF joint of {source or 'the robot'}")
        for key, value in e.items():
            if key in SERVO_KEYS:
                continue  # the drive law's keys: read_servo
            try:
                value = float(value)
            except (TypeError, ValueError):
                raise RobotError(f"{where}: {key} = {value!r} for {pattern!r} is not a number") from None
            if key in ("kp", "kd", "effort", "armature", "friction", "damping") and not value >= 0.0:
                raise RobotError(f"{where}: {key} = {value} for {pattern!r} must be >= 0")
            lst = getattr(builder, attr[key])
            for j in hits:
                lst[qd_start[j]] = value
                if key == "effort":
                    effort_dofs.add(int(qd_start[j]))
    # a joint given gains but still in "no drive" mode would ignore them
    import newton

    for j in range(len(labels)):
        if dof_dim[j] == 1:
            d = qd_start[j]
            if builder.joint_target_ke[d] > 0.0 or builder.joint_target_kd[d] > 0.0:
                builder.joint_target_mode[d] = int(newton.JointTargetMode.POSITION)
    return effort_dofs
