"""One robot file into a :class:`newton.ModelBuilder`: Newton's importers, plus what they leave out but the file
states.

Read here: the force range of MJCF actuators (compiled by MuJoCo itself, defaults classes resolved) and, in a USD
converted from MJCF, the ``mjc:`` attributes (joint ``mjc:actuatorfrcrange``; ``MjcActuator`` prims'
``mjc:forceRange``, ``mjc:gainPrm`` and ``mjc:biasPrm``). An effort limit that nothing states keeps Newton's
placeholder (1e6) and is refused by :meth:`~wresdyn.robot.description.Robot.check_effort` before any replay, with
the fix in the message (``effort = ...`` in a gains config).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .packages import resolved_urdf

__all__ = ["import_file", "dof_by_label", "short_label", "resolve_path", "SUFFIX_KIND"]

SUFFIX_KIND = {".usd": "usd", ".usda": "usd", ".usdc": "usd", ".usdz": "usd", ".urdf": "urdf", ".xml": "mjcf",
               ".mjcf": "mjcf"}
"""The robot file's kind by its suffix (lower case)."""


def resolve_path(path: str | Path) -> Path:
    """A robot path; ``newton:NAME`` names an asset bundled with newton (e.g. ``newton:quadruped.urdf``)."""
    text = str(path)
    if text.startswith("newton:"):
        import importlib.util

        spec = importlib.util.find_spec("newton")
        return Path(spec.origin).parent / "examples" / "assets" / text.removeprefix("newton:")
    return Path(path)


def short_label(label: str) -> str:
    """A label's last path element: the name of a joint, body or shape."""
    return label.rstrip("/").split("/")[-1]


def import_file(builder, path: Path, kind: str, floating: bool, package_path=None) -> None:
    """Add the robot file ``path`` of ``kind`` (``"usd"``, ``"urdf"`` or ``"mjcf"``) to ``builder``, with what Newton's
    importer leaves out. A URDF's ``package://`` mesh URIs are resolved first (:mod:`wresdyn.robot.packages`; user
    roots ``package_path``, default ``--package-path``); one that names no file raises
    :class:`~wresdyn.errors.RobotError`."""
    if kind == "usd":
        builder.add_usd(str(path), floating=floating, enable_self_collisions=False, load_visual_shapes=False)
        _usd_mjc_attributes(builder, path)
    elif kind == "urdf":
        xml = resolved_urdf(path, package_path)
        builder.add_urdf(str(path) if xml is None else xml, floating=floating, enable_self_collisions=False)
    else:
        builder.add_mjcf(str(path), floating=floating, enable_self_collisions=False, parse_visuals=False)
        _mjcf_actuator_limits(builder, path)


def dof_by_label(builder) -> dict[str, int]:
    """Joint label (full USD prim path or MJCF path) -> DoF index, for 1-DoF joints."""
    out = {}
    for j, label in enumerate(builder.joint_label):
        lin, ang = builder.joint_dof_dim[j]
        if int(lin) + int(ang) == 1:
            out[label] = int(builder.joint_qd_start[j])
    return out


def _tighten_effort(builder, dof: int, limit: float) -> None:
    """Lower a DoF's effort limit to ``limit`` (the file states both: the tighter one bounds the torque)."""
    current = float(builder.joint_effort_limit[dof])
    if limit > 0.0 and np.isfinite(limit) and (not current > 0.0 or limit < current):
        builder.joint_effort_limit[dof] = limit


def _mjcf_actuator_limits(builder, path: Path) -> None:
    """Effort limits from MJCF actuators, which Newton's MJCF importer leaves out: compiled by MuJoCo (so
    default classes and ``autolimits`` resolve as MuJoCo does), every force-limited actuator on a joint bounds
    that joint's effort by ``|gear| * max(|forcerange|)``. Newton already reads the joint's own
    ``actuatorfrcrange`` and a position actuator's ``kp``/``kv``. A file MuJoCo cannot compile is left as
    Newton read it."""
    try:
        import mujoco

        m = mujoco.MjModel.from_xml_path(str(path))
    except Exception:  # Newton extensions MuJoCo does not know: keep what Newton read
        return
    by_name: dict[str, list[int]] = {}
    for label, dof in dof_by_label(builder).items():
        by_name.setdefault(short_label(label), []).append(dof)
    for a in range(m.nu):
        if int(m.actuator_trntype[a]) != int(mujoco.mjtTrn.mjTRN_JOINT) or not m.actuator_forcelimited[a]:
            continue
        name = mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_JOINT, int(m.actuator_trnid[a, 0]))
        dofs = by_name.get(name or "", [])
        if len(dofs) == 1:
            limit = abs(float(m.actuator_gear[a, 0])) * float(np.abs(m.actuator_forcerange[a]).max())
            _tighten_effort(builder, dofs[0], limit)


def _usd_mjc_attributes(builder, path: Path) -> None:
    """MuJoCo attributes of a USD converted from MJCF that Newton's default USD import leaves out: a joint's
    ``mjc:actuatorfrcrange:min/max`` (with ``mjc:actuatorfrclimited``) and, for an ``MjcActuator`` prim whose
    ``mjc:target`` is a 1-DoF joint, its ``mjc:forceRange:min/max`` (with ``mjc:forceLimited`` and
    ``mjc:gear``) bound the effort; its ``mjc:gainPrm`` / ``mjc:biasPrm`` give kp and kd when they have the
    position-actuator shape (gain ``[kp]``, bias ``[0, -kp, -kv]``) and Newton found no drive on the joint."""
    if not _has_text(path, b"mjc:"):
        return
    from pxr import Usd

    stage = Usd.Stage.Open(str(path))
    if stage is None:
        return
    dofs = dof_by_label(builder)

    def value(prim, name, default=None):
        attr = prim.GetAttribute(name)
        return attr.Get() if attr and attr.HasAuthoredValue() else default

    def limit(prim, rng: str, limited: str) -> float | None:
        lo, hi = value(prim, f"{rng}:min"), value(prim, f"{rng}:max")
        if lo is None and hi is None:
            return None
        lo, hi = float(lo or 0.0), float(hi or 0.0)
        flag = str(value(prim, limited, "auto"))
        return max(abs(lo), abs(hi)) if flag == "true" or (flag == "auto" and lo < hi) else None

    import newton

    for prim in stage.Traverse():
        path_str = str(prim.GetPath())
        if path_str in dofs:
            e = limit(prim, "mjc:actuatorfrcrange", "mjc:actuatorfrclimited")
            if e is not None:
                _tighten_effort(builder, dofs[path_str], e)
        if prim.GetTypeName() != "MjcActuator":
            continue
        rel = prim.GetRelationship("mjc:target")
        targets = [str(t) for t in rel.GetTargets()] if rel else []
        if len(targets) != 1 or targets[0] not in dofs:
            continue
        dof = dofs[targets[0]]
        gear = list(value(prim, "mjc:gear", None) or [1.0])
        e = limit(prim, "mjc:forceRange", "mjc:forceLimited")
        if e is not None:
            _tighten_effort(builder, dof, abs(float(gear[0])) * e)
        gain, bias = value(prim, "mjc:gainPrm"), value(prim, "mjc:biasPrm")
        if gain is None or bias is None or len(gain) < 1 or len(bias) < 3:
            continue
        kp, kv = float(gain[0]), -float(bias[2])
        position_shaped = kp > 0 and abs(float(bias[0])) < 1e-12 and abs(float(bias[1]) + kp) <= 1e-9 * kp and kv >= 0
        if position_shaped and float(gear[0]) == 1.0 and not builder.joint_target_ke[dof] > 0 \
                and not builder.joint_target_kd[dof] > 0:
            builder.joint_target_ke[dof], builder.joint_target_kd[dof] = kp, kv
            builder.joint_target_mode[dof] = int(newton.JointTargetMode.POSITION)


def _has_text(path: Path, needle: bytes) -> bool:
    """Whether a (text or binary) USD file mentions ``needle`` at all: skips opening the stage twice for files
    without MuJoCo attributes."""
    with open(path, "rb") as f:
        tail = b""
        for chunk in iter(lambda: f.read(1 << 20), b""):
            if needle in tail + chunk:
                return True
            tail = chunk[-len(needle):]
    return False
