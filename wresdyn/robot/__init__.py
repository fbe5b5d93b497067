"""Stage 1, the robot: one robot file (USD, URDF or MJCF) -> one :class:`Robot` description, and the same
robot as MuJoCo C and Pinocchio models built from it field by field; :mod:`.ground`: the robot on a floor (contact
settings shared by Newton and MuJoCo C, the floating-base state, a standing start)."""

from .description import DEFAULT_ROBOT, Robot, RobotError, apply_overrides, load_robot, resolve_path
from .ground import ContactSettings, FloatingState, standing_state

__all__ = ["DEFAULT_ROBOT", "ContactSettings", "FloatingState", "Robot", "RobotError", "apply_overrides",
           "load_robot", "resolve_path", "standing_state"]
