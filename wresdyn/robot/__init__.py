"""Stage 1, the robot: one robot file (USD, URDF or MJCF) -> one :class:`Robot` description, and the same
robot as MuJoCo C and Pinocchio models built from it field by field."""

from .description import DEFAULT_ROBOT, Robot, RobotError, apply_overrides, load_robot, resolve_path

__all__ = ["DEFAULT_ROBOT", "Robot", "RobotError", "apply_overrides", "load_robot", "resolve_path"]
