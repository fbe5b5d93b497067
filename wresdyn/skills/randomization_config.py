"""The domain randomisation's settings (:class:`Randomization`), apart from the code that draws them
(:mod:`wresdyn.skills.randomize`, which needs torch): the command line builds its flags from this class, and a
command's help must not import torch."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Literal

from ..errors import WresdynError

__all__ = ["Randomization", "UNSEEN_FIELDS"]


@dataclass(frozen=True)
class Randomization:
    """Wide domain randomisation, the ranges of the peers' humanoid tasks (scaled to this humanoid: 35 kg, as the
    Unitree G1 those tasks drive). Scale ranges multiply the centre (the robot file's value); absolute ones replace
    or offset it."""

    mass_scale: tuple[float, float] = (0.8, 1.2)
    """Factor on every moving link's mass, its inertia scaled alike [-]. Source: ``zengliangjun/IGL``
    ``humanoidverse/simulator/isaacsim45/event_cfg.py`` (IsaacLab ``randomize_rigid_body_mass``,
    ``mass_distribution_params (0.8, 1.2)``, ``operation "scale"``); IsaacLab's own
    ``locomotion/velocity/velocity_env_cfg.py`` adds (-5, 5) kg to the base (disabled there: NaNs), 14 % of a
    35 kg robot."""
    com_offset: tuple[float, float, float] = (0.025, 0.05, 0.05)
    """Half-ranges of the offset of ``com_body``'s centre of mass along x, y, z [m]. Source: ``mujocolab/mjlab``
    ``src/mjlab/tasks/tracking/tracking_env_cfg.py`` ``base_com`` (``torso_link`` ``body_ipos`` add
    x ±0.025, y ±0.05, z ±0.05 m, startup); IsaacLab ``velocity_env_cfg.py`` ``base_com``: x, y ±0.05,
    z ±0.01 m."""
    com_body: str = "torso"
    """The link whose centre of mass moves (mjlab's ``torso_link``)."""
    kp_scale: tuple[float, float] = (0.8, 1.2)
    """Factor on the PD stiffness [-]: IsaacLab ``randomize_actuator_gains`` ``stiffness_distribution_params``,
    (0.8, 1.2) and (0.9, 1.1) the recurring humanoid settings of IsaacLab-based task configs (the IsaacLab
    locomotion configs themselves leave the gains alone)."""
    kd_scale: tuple[float, float] = (0.8, 1.2)
    """Factor on the PD damping [-]: ``damping_distribution_params``, as ``kp_scale``."""
    friction: tuple[float, float] = (0.0, 0.05)
    """Dry joint friction as a fraction of the joint's effort limit [-] (absolute, not a factor: the robot file's
    friction is 0, which IsaacLab's ``randomize_joint_parameters`` ``friction_distribution_params (0.5, 1.25)``
    ``"scale"`` would leave at 0). 0.05 of the limit is the identification's friction unit
    (:class:`~wresdyn.sim.physics.PhysicsModel` ``ref``)."""
    armature_scale: tuple[float, float] = (0.8, 1.2)
    """Factor on the joint armature [-]: IsaacLab ``randomize_joint_parameters`` ``armature_distribution_params``
    (0.8, 1.2), the recurring humanoid setting of IsaacLab-based task configs."""
    effort_scale: tuple[float, float] = (0.9, 1.1)
    """Factor on the effort limits [-]: mjlab's ``dr`` module randomises ``effort_limits``; no humanoid task config
    read here sets a range, so ±10 % (a stated rule)."""
    delay: tuple[float, float] = (0.0, 0.02)
    """Command delay [s], per world (all joints alike): up to one policy period at 50 Hz (a stated rule: the
    peers' tracking configs read here add no delay; humanoid sim-to-real work randomises 0-20 ms)."""
    floor_friction: tuple[float, float] = (0.3, 1.2)
    """Robot-floor sliding friction [-] (floor only). Source: mjlab ``tracking_env_cfg.py`` ``foot_friction``
    (``geom_friction`` abs (0.3, 1.2), startup); IsaacLab's static friction 0.8 / dynamic 0.6 (disabled there)."""
    redraw: Literal["reset", "startup"] = "reset"
    """Draw again for every world an episode resets, or once at construction."""
    seed: int = 0
    """Seed of the draws."""
    unseen: Literal["narrow", "wide"] = "narrow"
    """(f)'s range of a parameter its identifiability report marks unseen (no finite error: the stand's data carry
    no trace of it), read from the report alone: ``"narrow"`` ±:data:`NARROW_DEFAULT` like any parameter without an
    error; ``"wide"`` (e)'s range (``unseen_mass_add_kg`` for a link's mass, ``unseen_effort_scale`` for an effort
    limit, where set) and, when ``com_body``'s
    mass is unseen, (e)'s whole CoM offset (``unseen_com_offset``, where set) instead of :data:`NARROW_DEFAULT` of
    it. (e) is untouched."""
    unseen_mass_add_kg: tuple[float, float] | None = None
    """With ``unseen="wide"``: the mass added to an unseen link [kg], drawn as the factor (m+lo)/m..(m+hi)/m on its
    identified mass m (its inertia alike, at least a tenth of m), instead of ``mass_scale`` (``None``). Sourced
    value (-5.0, 5.0): IsaacLab ``locomotion/velocity/velocity_env_cfg.py`` ``add_base_mass``
    (``randomize_rigid_body_mass``, ``mass_distribution_params (-5.0, 5.0)``, ``operation "add"``, the base link)."""
    unseen_com_offset: tuple[float, float, float] | None = None
    """With ``unseen="wide"`` and ``com_body``'s mass unseen: the half-ranges of its CoM offset along x, y, z [m]
    instead of ``com_offset`` (``None``). Sourced value (0.05, 0.05, 0.01): IsaacLab ``velocity_env_cfg.py``
    ``base_com`` (x, y ±0.05, z ±0.01 m)."""
    unseen_effort_scale: tuple[float, float] | None = None
    """With ``unseen="wide"``: the factor range of an effort limit the report marks unseen, instead of
    ``effort_scale`` (``None``), drawn as effort factors are (log-uniform, uniform where ``effort_from_data`` sets a
    joint so). Sourced value (0.8, 1.2): TWIST's humanoid motion-tracking recipe (``g1_mimic_distill_config.py``:
    ``randomize_motor = True``, ``motor_strength_range = [0.8, 1.2]``, a factor on every motor's torque), here on
    the limits the stand's data cannot see."""

    effort_from_data: bool = False
    """(f) only: draw the effort limit of each joint whose drive the identification's training data saturate on fewer
    than the report's ``effort_saturated_min`` of the samples (1 %) uniformly from the torque those data demand of it
    without saturating (the report's ``demanded_effort_nm``) up to the upper end of its range otherwise, instead of
    that range. Source: the data's lower bound. The drive delivered every torque the data demand of it, so its limit is
    at least the largest of them (:mod:`wresdyn.identify.unexcited_limits`); where it (almost) never saturates, the
    data say nothing of how far above that bound the limit lies, and the identified value there is the fit's start
    or the shared derating. A limit the data saturate on more samples keeps its range. Needs a report that records
    the demand; an older one is refused."""

    def __post_init__(self) -> None:
        if self.unseen not in ("narrow", "wide"):
            raise WresdynError(f"randomization.unseen: 'narrow' or 'wide', got {self.unseen!r}")
        if self.unseen == "narrow" and (self.unseen_mass_add_kg, self.unseen_com_offset,
                                        self.unseen_effort_scale) != (None, None, None):
            raise WresdynError("randomization.unseen-mass-add-kg / unseen-com-offset / unseen-effort-scale act only "
                               "with --randomization.unseen wide")
        add = self.unseen_mass_add_kg
        if add is not None and not (len(add) == 2 and all(math.isfinite(x) for x in add) and add[0] < add[1]):
            raise WresdynError(f"randomization.unseen_mass_add_kg: (lo, hi) kg with lo < hi, got {add}")
        com = self.unseen_com_offset
        if com is not None and not (len(com) == 3 and all(math.isfinite(x) and x >= 0 for x in com)):
            raise WresdynError(f"randomization.unseen_com_offset: three half-ranges >= 0 m, got {com}")
        eff = self.unseen_effort_scale
        if eff is not None and not (len(eff) == 2 and all(math.isfinite(x) and x > 0 for x in eff)
                                    and eff[0] < eff[1]):
            raise WresdynError(f"randomization.unseen_effort_scale: (lo, hi) factors with 0 < lo < hi, got {eff}")

    def record(self, narrow: bool = True) -> dict:
        """The fields as a run records them (``config.json``, ``results.json``): the :data:`UNSEEN_FIELDS` only with
        ``unseen="wide"`` (``unseen_effort_scale`` only when set) and ``effort_from_data`` only when on, all for (f)
        alone (``narrow``; (e) never reads them), so that every run recorded before them reads the same and resumes,
        (e)'s whatever they are."""
        out = asdict(self)
        if self.unseen == "narrow" or not narrow:
            for f in UNSEEN_FIELDS:
                del out[f]
        elif self.unseen_effort_scale is None:
            del out["unseen_effort_scale"]
        if not (self.effort_from_data and narrow):
            del out["effort_from_data"]
        return out


UNSEEN_FIELDS = ("unseen", "unseen_mass_add_kg", "unseen_com_offset", "unseen_effort_scale")
"""The fields of :class:`Randomization` that change only (f)'s ranges of unseen parameters."""
