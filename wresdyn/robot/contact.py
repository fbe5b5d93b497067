"""Robot-floor contact settings, stated once and written into both simulators: Newton's shapes and solver options
(:meth:`wresdyn.robot.description.Robot.build_model` with ``ground=True``, :mod:`wresdyn.sim.solvers`) and the
MuJoCo C model (:func:`wresdyn.robot.mujoco_model.build_mujoco`); :mod:`wresdyn.robot.ground` explains why they
must agree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

from ..choices import check_number
from ..errors import RobotError

__all__ = ["ContactSettings"]


@dataclass(frozen=True)
class ContactSettings:
    """Robot-floor contact, the same in Newton and in MuJoCo C. The defaults are MuJoCo's own defaults, which are
    also Newton's (``ShapeConfig`` mu 1, ke 2500, kd 100 convert to solref (0.02, 1)), except ``gap`` (Newton 0.1:
    inactive contacts, which nothing here reads, cost time)."""

    friction: float = 1.0
    """Sliding friction coefficient [-] of every collision shape and of the floor (MuJoCo geom ``friction[0]``,
    Newton ``shape_material_mu``); MuJoCo takes the larger of two geoms', so this is the robot-floor friction."""
    torsional_friction: float = 0.005
    """Torsional friction [m] (geom ``friction[1]``, Newton ``mu_torsional``); inactive at ``condim`` 3."""
    rolling_friction: float = 0.0001
    """Rolling friction [m] (geom ``friction[2]``, Newton ``mu_rolling``); inactive at ``condim`` 3."""
    timeconst: float = 0.02
    """Contact time constant [s] (geom ``solref[0]``); Newton: ``shape_material_kd = 2 / timeconst``. Keep it above
    2 dt (MuJoCo clamps it there)."""
    dampratio: float = 1.0
    """Contact damping ratio [-] (geom ``solref[1]``); Newton: ``ke = 1 / (timeconst * dampratio)^2``."""
    gap: float = 0.0
    """Extra distance of inactive contacts [m] (geom ``gap``, Newton ``shape_gap``)."""
    cone: str = "pyramidal"
    """Friction cone (``"pyramidal"`` or ``"elliptic"``), MuJoCo option ``cone``."""
    iterations: int = 100
    """Constraint solver iterations (MuJoCo option ``iterations``)."""
    ls_iterations: int = 50
    """Line-search iterations (MuJoCo option ``ls_iterations``)."""
    impratio: float = 1.0
    """Frictional-to-normal impedance ratio [-] (MuJoCo option ``impratio``)."""

    margin: ClassVar[float] = 0.0
    """Distance at which a contact becomes active [m] (geom ``margin``, Newton ``shape_margin``); not a setting:
    ``SolverMuJoCo`` zeroes every geom margin of a model with boxes (MuJoCo's native box collision rejects them,
    Newton issue 2106)."""
    condim: ClassVar[int] = 3
    """Contact dimensionality: normal and two sliding directions. What ``SolverMuJoCo`` writes for a shape without
    a ``mujoco:condim`` attribute (MuJoCo's default); not a setting."""
    solimp: ClassVar[tuple] = (0.9, 0.95, 0.001, 0.5, 2.0)
    """Constraint impedance, MuJoCo's default, which ``SolverMuJoCo`` writes for a shape without a
    ``mujoco:geom_solimp`` attribute; not a setting."""
    solver: ClassVar[str] = "newton"
    """MuJoCo's constraint solver (its default and Newton's)."""

    def __post_init__(self):
        for name in ("friction", "torsional_friction", "rolling_friction", "gap", "impratio"):
            check_number(getattr(self, name), f"contact {name}", ge=0.0)
        for name in ("timeconst", "dampratio"):
            check_number(getattr(self, name), f"contact {name}", gt=0.0)
        for name in ("iterations", "ls_iterations"):
            check_number(getattr(self, name), f"contact {name}", integer=True, ge=1)
        if self.cone not in ("pyramidal", "elliptic"):
            raise RobotError(f"contact cone = {self.cone!r} is not one of: pyramidal, elliptic")

    @property
    def solref(self) -> tuple[float, float]:
        """MuJoCo ``solref`` (time constant [s], damping ratio [-])."""
        return (self.timeconst, self.dampratio)

    @property
    def ke(self) -> float:
        """Newton contact stiffness ``shape_material_ke`` that ``SolverMuJoCo`` converts back to :attr:`solref`."""
        return 1.0 / (self.timeconst * self.dampratio) ** 2

    @property
    def kd(self) -> float:
        """Newton contact damping ``shape_material_kd`` that ``SolverMuJoCo`` converts back to :attr:`solref`."""
        return 2.0 / self.timeconst
