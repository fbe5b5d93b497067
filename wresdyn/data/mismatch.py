"""The mismatch config: how the simulated "real" robot (:class:`~wresdyn.data.real_robot.RealRobot`) differs from
the nominal model (physics, PD gains, delay, torque limits, sensors and, standing on a floor, the floor's friction and
softness), as global scalars and per-joint / per-link entries, read from TOML with its keys, types and signs checked,
and applied to the robot's MuJoCo model (:func:`perturb_mujoco`, :func:`floor_contact`)."""

from __future__ import annotations

import dataclasses
import fnmatch
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tomllib

from ..robot.contact import ContactSettings
from ..robot.description import RobotError

__all__ = ["Mismatch", "MismatchError", "JOINT_KEYS", "LINK_KEYS", "perturb_mujoco", "floor_contact"]


class MismatchError(RobotError):
    """A mismatch config that cannot be used; the message is one line naming the file."""


@dataclass(frozen=True)
class Mismatch:
    """How the real robot differs from the nominal model. The defaults are all off (the nominal robot)."""

    friction: float = 0.0
    """Coulomb (dry) joint friction torque as a fraction of each joint's effort limit [-] (MuJoCo frictionloss,
    added to the model's own)."""
    damping: float = 0.0
    """Viscous joint damping as a fraction of each joint's PD kd [-] (added to the model's own damping)."""
    armature_scale: float = 1.0
    """Factor on every joint's reflected rotor inertia (armature) [-]."""
    mass_error: float = 0.0
    """Relative standard deviation of each link's mass error [-]; the link's inertia scales with it."""
    com_error: float = 0.0
    """Standard deviation of each link's centre-of-mass offset, per axis [m]."""
    inertia_error: float = 0.0
    """Relative standard deviation of each principal moment of inertia, on top of the mass scaling [-]."""
    kp_scale: float = 1.0
    """Factor on every joint's PD stiffness [-]."""
    kd_scale: float = 1.0
    """Factor on every joint's PD damping [-]."""
    gain_error: float = 0.0
    """Relative standard deviation of a per-joint factor on kp and kd, on top of the scales [-]."""
    delay: float = 0.0
    """Actuator delay: a command reaches the motor this much later [s], rounded to whole substeps."""
    torque_limit_scale: float = 1.0
    """Factor on every joint's effort limit (torque saturation) [-]; joints without a limit stay unlimited."""
    position_noise: float = 0.0
    """Standard deviation of the white noise on measured joint positions [rad]."""
    velocity_noise: float = 0.0
    """Standard deviation of the white noise on measured joint velocities [rad/s]."""
    encoder_resolution: float = 0.0
    """Measured positions are rounded to multiples of this (encoder quantisation) [rad]; 0 = off."""
    velocity_resolution: float = 0.0
    """Measured velocities are rounded to multiples of this (the drive's velocity word) [rad/s]; 0 = off."""
    torque_resolution: float = 0.0
    """Recorded (diagnostic) torques are rounded to multiples of this [N*m]; 0 = off."""
    substep: float = 0.0
    """Physics step of the real robot [s], must divide the recording step; 0 = the recording step."""
    floor_friction_scale: float = 1.0
    """Factor on the floor's sliding friction coefficient (:attr:`~wresdyn.robot.contact.ContactSettings.friction`,
    nominally 1) [-]; a robot on a floor only (a stand has none)."""
    floor_timeconst_scale: float = 1.0
    """Factor on the floor contact's time constant (:attr:`~wresdyn.robot.contact.ContactSettings.timeconst`, MuJoCo
    ``solref[0]``, nominally 0.02 s) [-]: above 1 a softer floor, which the feet sink into further (the static
    deflection grows with its square); a robot on a floor only."""
    seed: int = 0
    """Seed of the per-link and per-joint errors (one fixed "physical" robot)."""
    joint: tuple = ()
    """Per-joint entries ``{"match": fnmatch pattern, key: value}`` overriding the global scalars on the joints
    they match, in order (later entries win); keys: :data:`JOINT_KEYS`. TOML: ``[[joint]]`` tables."""
    link: tuple = ()
    """Per-link entries ``{"match": pattern on the body name, ...}`` applied on top of the random link errors;
    keys :data:`LINK_KEYS`: ``mass_scale`` [-] (inertia scales with it), ``com_offset`` [m] (3 numbers, body
    frame), ``inertia_scale`` [-]. TOML: ``[[link]]`` tables."""

    @classmethod
    def load(cls, path: str | Path) -> "Mismatch":
        """Read a TOML file of ``key = value`` lines (keys: the field names); unknown keys are an error."""
        path = Path(path)
        if not path.is_file():
            raise MismatchError(f"{path}: mismatch config not found")
        try:
            data = tomllib.loads(path.read_text())
        except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
            raise MismatchError(f"{path}: malformed TOML: {e}") from None
        return cls.from_dict(data, where=str(path))

    @classmethod
    def from_dict(cls, data: dict, where: str = "mismatch config") -> "Mismatch":
        """Build from a dict, checking keys, types and signs."""
        fields = {f.name: f for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - set(fields))
        if unknown:
            raise MismatchError(f"{where}: unknown key(s) {unknown}; allowed: {list(fields)}")
        values = {}
        for key, allowed in (("joint", JOINT_KEYS), ("link", LINK_KEYS)):
            if key in data:
                values[key] = tuple(_entry(e, allowed, f"{where}: [[{key}]] {i}") for i, e in enumerate(data[key]))
        for key, value in data.items():
            if key in ("joint", "link"):
                continue
            want = int if key == "seed" else float
            if isinstance(value, bool) or not isinstance(value, int if want is int else (int, float)):
                raise MismatchError(f"{where}: {key} = {value!r} must be {'an integer' if want is int else 'a number'}")
            value = want(value)
            if want is float and not (np.isfinite(value) and value >= 0.0):
                raise MismatchError(f"{where}: {key} = {value} must be finite and >= 0")
            values[key] = value
        for key in ("armature_scale", "kp_scale", "torque_limit_scale", "floor_timeconst_scale"):
            if key in values and values[key] <= 0.0:
                raise MismatchError(f"{where}: {key} = {values[key]} must be > 0")
        return cls(**values)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["joint"], d["link"] = [dict(e) for e in self.joint], [dict(e) for e in self.link]
        return d

    def is_nominal(self) -> bool:
        """True when the physics and sensors are those of the nominal model (``substep`` and ``seed`` aside)."""
        ignore = ("substep", "seed", "joint", "link")
        if self.joint or self.link:
            return False
        return all(getattr(self, f.name) == f.default for f in dataclasses.fields(self) if f.name not in ignore)


JOINT_KEYS = ("friction", "damping", "armature_scale", "kp_scale", "kd_scale", "torque_limit_scale")
"""Keys of a ``[[joint]]`` mismatch entry (besides ``match``): the per-joint forms of the global scalars."""
LINK_KEYS = ("mass_scale", "com_offset", "inertia_scale")
"""Keys of a ``[[link]]`` mismatch entry (besides ``match``)."""


def _entry(e, allowed, where: str) -> dict:
    """Check one per-joint / per-link entry: a pattern and known keys with finite, sensible values."""
    if not isinstance(e, dict) or not isinstance(e.get("match"), str):
        raise MismatchError(f"{where}: needs match = \"PATTERN\"")
    out = {"match": e["match"]}
    for k, v in e.items():
        if k == "match":
            continue
        if k not in allowed:
            raise MismatchError(f"{where}: unknown key {k!r}; allowed: match, {', '.join(allowed)}")
        if k == "com_offset":
            if not (isinstance(v, list | tuple) and len(v) == 3 and all(isinstance(x, int | float) and
                                                                         np.isfinite(x) for x in v)):
                raise MismatchError(f"{where}: com_offset must be 3 numbers [m]")
            out[k] = tuple(float(x) for x in v)
            continue
        if isinstance(v, bool) or not isinstance(v, int | float) or not np.isfinite(v) or v < 0:
            raise MismatchError(f"{where}: {k} = {v!r} must be a finite number >= 0")
        if k.endswith("_scale") and v <= 0:
            raise MismatchError(f"{where}: {k} = {v} must be > 0")
        out[k] = float(v)
    return out


def _matches(names, pattern: str, what: str, source) -> np.ndarray:
    hits = np.array([fnmatch.fnmatchcase(n, pattern) for n in names], dtype=bool)
    if not hits.any():
        raise MismatchError(f"mismatch: [[{what}]] pattern {pattern!r} matches no {what} of {source}")
    return hits


def perturb_mujoco(m, mm: Mismatch, r, v0: int, rng: np.random.Generator) -> None:
    """Apply the physical mismatch ``mm`` to the fields of ``m``, the compiled MuJoCo model of the robot ``r`` (a
    :class:`~wresdyn.robot.description.Robot`), in place; MuJoCo dof ``v0 + i`` is joint i (6 after a free joint);
    ``rng`` draws the random errors."""
    n = r.n_dof
    # per-link errors; body 0 of MuJoCo is the world, MuJoCo body i+1 is robot body i
    nb = m.nbody - 1
    mass_f = np.clip(1.0 + mm.mass_error * rng.standard_normal(nb), 0.3, None)
    com_d = mm.com_error * rng.standard_normal((nb, 3))
    inertia_f = np.clip(1.0 + mm.inertia_error * rng.standard_normal((nb, 3)), 0.3, None)
    for e in mm.link:
        hits = _matches(r.body_names, e["match"], "link", r.source)
        mass_f[hits] *= e.get("mass_scale", 1.0)
        com_d[hits] += np.asarray(e.get("com_offset", (0.0, 0.0, 0.0)))
        inertia_f[hits] *= e.get("inertia_scale", 1.0)
    m.body_mass[1:] *= mass_f
    m.body_ipos[1:] += com_d
    m.body_inertia[1:] *= mass_f[:, None] * inertia_f
    # joints (MuJoCo dof v0 + i is robot joint i, actuator i drives it): global, then per joint
    jv = {k: np.full(n, float(getattr(mm, k))) for k in JOINT_KEYS}
    for e in mm.joint:
        hits = _matches(r.joint_names, e["match"], "joint", r.source)
        for k, v in e.items():
            if k != "match":
                jv[k][hits] = v
    effort = np.where(np.isfinite(r.effort), r.effort, 0.0)
    dof = slice(v0, v0 + n)
    m.dof_armature[dof] *= jv["armature_scale"]
    m.dof_damping[dof] += jv["damping"] * r.kd
    m.dof_frictionloss[dof] += jv["friction"] * effort
    gain_f = np.clip(1.0 + mm.gain_error * rng.standard_normal((2, n)), 0.3, None)
    kp, kd = r.kp * jv["kp_scale"] * gain_f[0], r.kd * jv["kd_scale"] * gain_f[1]
    m.actuator_gainprm[:n, 0] = kp
    m.actuator_biasprm[:n, 1] = -kp
    m.actuator_biasprm[:n, 2] = -kd
    m.actuator_forcerange[:n] *= jv["torque_limit_scale"][:, None]


def floor_contact(mm: Mismatch, contact: ContactSettings | None = None) -> ContactSettings:
    """The real floor: ``contact`` (default ``ContactSettings()``, the nominal floor both simulators share) with the
    mismatch's friction and softness. A mismatch without floor fields (an older file or dataset header) gives the
    nominal floor."""
    c = contact or ContactSettings()
    return dataclasses.replace(c, friction=c.friction * mm.floor_friction_scale,
                               timeconst=c.timeconst * mm.floor_timeconst_scale)
