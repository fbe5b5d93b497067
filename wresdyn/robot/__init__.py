"""The robot: one robot file (USD, URDF or MJCF) -> one :class:`Robot` description, and the same
robot as MuJoCo C and Pinocchio models built from it field by field; :mod:`.file_import`: the robot file into a
Newton builder, with what Newton's importers leave out; :mod:`.packages`: a URDF's ``package://`` mesh URIs resolved
(``--package-path``); :mod:`.gains`: per-joint overrides of the file's drive and
joint parameters; :mod:`.contact`: the robot-floor contact settings shared by Newton and MuJoCo C; :mod:`.ground`:
the robot on a floor (collision shapes, the floating-base state, a standing start); :mod:`.physical`: its
physical parameters as fitted quantities."""

from .description import DEFAULT_ROBOT, Robot, RobotError, load_robot
from .file_import import resolve_path
from .gains import apply_overrides
from .contact import ContactSettings
from .ground import FloatingState, standing_state

__all__ = ["DEFAULT_ROBOT", "ContactSettings", "FloatingState", "Robot", "RobotError", "apply_overrides",
           "load_robot", "resolve_path", "standing_state"]
