"""``wresdyn export RUN``: the calibrated robot as USD layers over the robot file, Newton actuators and the residual.

What an export folder holds (written to a temporary folder and renamed into place, so a failed export leaves
nothing behind):

=====================  ========================================================================================
``robot.usda``         a layer whose sublayer is the original robot file (untouched, referenced by a relative
                       path): the identified physical parameters as the attributes Newton's USD importer reads:
                       per joint ``drive:angular:physics:stiffness/damping`` (per degree, the USD convention) and
                       ``maxForce`` (effort limit), ``newton:armature`` [kg m²], ``newton:damping`` [N m s/rad],
                       ``newton:friction`` [N m] (angular gains and damping per degree, as the importer reads them); per link ``physics:mass`` [kg], ``physics:centerOfMass`` [m],
                       ``physics:diagonalInertia`` [kg m²] and ``physics:principalAxes`` (the inertia tensor's
                       eigenbasis). Loaded as it is, Newton's solvers run the identified physics under their own
                       joint drives, without the command delay and the residual.
``actuated.usda``      a layer over ``robot.usda`` that moves the drive path into ``newton.actuators``: one
                       ``NewtonActuator`` prim per joint with ``NewtonPDControlAPI`` (kp, kd),
                       ``NewtonActuatorDelayAPI`` (the identified delay in steps of the scope's ``wresdyn:actuatorRateHz``, the
                       recording rate: step the actuators at that rate)
                       and ``NewtonMaxEffortClampingAPI`` (the effort limit), the joints' own drives set to zero
                       so the PD is applied once; and a ``wresdyn_residual`` prim that references the residual
                       network (``residual.pt2``, ``residual.onnx``) with its joints, kind and rate.
``residual.pt2``       the residual network, a ``torch.export`` archive (:mod:`wresdyn.learn.network_file`), and
                       ``residual.onnx`` the same program as ONNX; observation [q, q̇, q̈, q_cmd] (rad, rad/s, rad/s², rad), (N, 4n);
                       output a joint torque [N m] added next to the actuators' (not clamped with them), as in
                       :class:`~wresdyn.sim.simulator.Simulator`.
``physics.json``       the identified parameters (:class:`~wresdyn.sim.physics.PhysicalParams`), ``export.json``
                       where they came from (run, dataset, robot file and its sha256).
=====================  ========================================================================================

Servo joints (``drive = "servo"``, :mod:`wresdyn.robot.servo`): their ``NewtonActuator`` prim in ``actuated.usda``
applies ``WresdynServoControlAPI`` in place of the PD (the drive of :mod:`wresdyn.export.servo_actuator`: dead band,
goal-acceleration profile, back-EMF damping U / w0, backlash, encoder offset, startup torque) with Newton's ``NewtonActuatorDelayAPI`` and
``NewtonDCMotorClampingAPI`` (stall torque U, no-load speed w0; ``NewtonMaxEffortClampingAPI`` where w0 = 0), which
together are the servo law. ``robot.usda`` records ``wresdyn:drive = "servo"`` and ``wresdyn:servo:deadband``
[rad], ``wresdyn:servo:noloadSpeed`` [rad/s], ``wresdyn:servo:goalAccel`` [rad/s²], ``wresdyn:servo:backlash`` and
``wresdyn:servo:encoderOffset`` [rad], ``wresdyn:servo:startupTorque`` [N m] on the joint (Newton's importer
does not read them: loaded as it is, the joint runs its PD drive). The servo's stiction has no Newton counterpart
and is dropped, and a run identified under the damper friction law (``friction_kappa``) exports its amplitudes as
``newton:friction``: ``export.json``'s ``notes`` say so (:mod:`wresdyn.export.usd_notes`). The folder then also holds
``servo_actuator.py`` (newton, warp and pxr only) and ``wresdyn_servo_schema/``, the codeless USD schema plugin
Newton's importer needs to see the custom schema; ``export.json`` names them under ``"servo"``. A plain script
calls ``servo_actuator.register()`` before it opens any USD stage. MJCF and URDF robots are converted to USD in
``source/`` first (:mod:`wresdyn.export.convert`), the layers go over it; ``export.json`` names it ``"converted"``.

:mod:`wresdyn.export.residual_torque` runs the residual in a plain Newton loop.
"""

from __future__ import annotations

import json
import math
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..data.dataset import load_dataset
from ..data.loading import dataset_robot
from ..evaluation.evaluate_run import run_friction_kappa
from ..learn.runs import run_physics
from ..robot.file_import import dof_by_label
from ..sim.physics import PhysicalParams
from .convert import converted_robot, converter_missing, is_usd
from .run_folder import ExportError, open_run
from .usd_notes import usd_notes

__all__ = ["ExportError", "check_usd_robot", "export_run", "write_export", "write_layers", "inertia_principal"]

ACTUATOR_SCOPE = "wresdyn_actuators"
"""Child of the robot's default prim that holds the actuator prims."""
RESIDUAL_PRIM = "wresdyn_residual"
"""Child of the robot's default prim that references the residual network."""
SERVO_SCHEMA = "WresdynServoControlAPI"
"""The applied schema of a servo joint's actuator prim (:mod:`wresdyn.export.servo_actuator`'s drive, which
imports newton: the export copies its file and schema plugin without importing it)."""
_SERVO_FILES = (Path(__file__).with_name("servo_actuator.py"), Path(__file__).with_name("wresdyn_servo_schema"))
"""The drive's file and its USD schema plugin folder, shipped next to the layers."""
_SERVO_ATTRS = {"wresdyn:servo:deadband": "deadband", "wresdyn:servo:noloadSpeed": "noload_speed",
                "wresdyn:servo:goalAccel": "goal_accel", "wresdyn:servo:backlash": "backlash",
                "wresdyn:servo:encoderOffset": "encoder_offset", "wresdyn:servo:startupTorque": "startup_torque"}
"""Servo parameters authored on a servo joint in ``robot.usda`` [rad, rad/s, rad/s², rad, rad, N m], by
PhysicalParams field."""


def inertia_principal(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal moments (3,) and the rotation quaternion (w, x, y, z) of their axes, for a symmetric 3×3
    inertia [kg m²]: ``inertia = R diag(moments) Rᵀ`` with R the quaternion's rotation (``physics:principalAxes``)."""
    w, v = np.linalg.eigh(0.5 * (inertia + inertia.T))
    if np.linalg.det(v) < 0:
        v[:, 0] = -v[:, 0]
    return w, _quat_from_matrix(v)


def _quat_from_matrix(r: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a rotation matrix (columns: the rotated axes)."""
    t = np.trace(r)
    if t > 0:
        s = 2.0 * math.sqrt(1.0 + t)
        q = [0.25 * s, (r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s]
    else:
        i = int(np.argmax(np.diag(r)))
        j, k = (i + 1) % 3, (i + 2) % 3
        s = 2.0 * math.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
        q = [0.0] * 4
        q[0] = (r[k, j] - r[j, k]) / s
        q[1 + i] = 0.25 * s
        q[1 + j] = (r[j, i] + r[i, j]) / s
        q[1 + k] = (r[k, i] + r[i, k]) / s
    q = np.array(q)
    return q / np.linalg.norm(q) * (1.0 if q[0] >= 0 else -1.0)


def _joint_paths(robot) -> list[str]:
    """USD prim path of each actuated joint, in ``robot.joint_names`` order."""
    by_dof = {dof: label for label, dof in dof_by_label(robot.builder).items()}
    return [by_dof[int(d)] for d in robot.qd_index]


def _copy_stage_metadata(src, dst) -> None:
    """Up axis and units of the robot file onto a layer over it."""
    for key in ("upAxis", "metersPerUnit", "kilogramsPerUnit"):
        if src.HasMetadata(key):
            dst.SetMetadata(key, src.GetMetadata(key))


def write_layers(robot, physics, out: Path, rate_hz: float, residual: dict | None = None) -> None:
    """Write ``robot.usda`` and ``actuated.usda`` into the folder ``out`` (module docstring).

    Args:
        robot: The robot (loaded from a USD file; its builder's labels are the prim paths).
        physics: :class:`~wresdyn.sim.physics.PhysicalParams` to author.
        out: Existing folder.
        rate_hz: Actuator step rate [Hz] the delay is counted in (``newton:timeStepsPerSecond``).
        residual: ``residual.json`` of the run (kind, joint names, rate), or ``None`` for no residual prim.
    """
    from pxr import Gf, Sdf, Usd, UsdPhysics

    physics.check(robot, "physics")
    servo = getattr(robot, "servo", None)
    src = Path(robot.source).resolve()
    root_path = out / "robot.usda"
    stage = Usd.Stage.CreateNew(str(root_path))
    stage.GetRootLayer().subLayerPaths.append(os.path.relpath(src, out.resolve()))
    base = Usd.Stage.Open(str(src))
    default = base.GetDefaultPrim()
    if not default:
        raise ExportError(f"{src}: the robot file has no default prim (USD defaultPrim); cannot layer over it")
    stage.SetDefaultPrim(stage.GetPrimAtPath(default.GetPath()))
    stage.GetRootLayer().documentation = (
        f"wresdyn calibrated robot: identified physical parameters over {src.name} (written by wresdyn export)")
    _copy_stage_metadata(base, stage)
    joint_paths = _joint_paths(robot)

    deg = math.pi / 180.0
    for i, path in enumerate(joint_paths):
        prim = stage.OverridePrim(path)
        prismatic = bool(robot.is_prismatic()[i])
        axis = "linear" if prismatic else "angular"
        per = 1.0 if prismatic else deg  # USD angular drive gains are per degree
        if not prim.HasAPI(UsdPhysics.DriveAPI, axis):  # a converted joint's drive may be a MuJoCo actuator prim
            UsdPhysics.DriveAPI.Apply(prim, axis)
        _set(prim, f"drive:{axis}:physics:stiffness", Sdf.ValueTypeNames.Float, physics.kp[i] * per)
        _set(prim, f"drive:{axis}:physics:damping", Sdf.ValueTypeNames.Float, physics.kd[i] * per)
        if np.isfinite(physics.effort[i]):
            _set(prim, f"drive:{axis}:physics:maxForce", Sdf.ValueTypeNames.Float, physics.effort[i])
        if "NewtonJointAPI" not in prim.GetAppliedSchemas():
            prim.AddAppliedSchema("NewtonJointAPI")
        _set(prim, "newton:armature", Sdf.ValueTypeNames.Float, physics.armature[i])
        _set(prim, "newton:damping", Sdf.ValueTypeNames.Float, physics.damping[i] * per)  # per degree too
        _set(prim, "newton:friction", Sdf.ValueTypeNames.Float, physics.friction[i])
        _set(prim, "wresdyn:delay", Sdf.ValueTypeNames.Double, physics.delay[i])  # [s], the identified delay
        if servo is not None and servo.mask[i]:  # read by actuated.usda's servo actuators, not by the importer
            _set(prim, "wresdyn:drive", Sdf.ValueTypeNames.Token, "servo")
            for attr, field in _SERVO_ATTRS.items():
                _set(prim, attr, Sdf.ValueTypeNames.Double, getattr(physics, field)[i])
    for b, path in enumerate(robot.builder.body_label):
        if not (physics.body_mass[b] > 0):
            continue
        prim = stage.OverridePrim(path)
        if not prim.HasAPI(UsdPhysics.MassAPI):
            UsdPhysics.MassAPI.Apply(prim)
        moments, quat = inertia_principal(physics.body_inertia[b])
        _set(prim, "physics:mass", Sdf.ValueTypeNames.Float, physics.body_mass[b])
        _set(prim, "physics:centerOfMass", Sdf.ValueTypeNames.Point3f, Gf.Vec3f(*map(float, physics.body_com[b])))
        _set(prim, "physics:diagonalInertia", Sdf.ValueTypeNames.Float3, Gf.Vec3f(*map(float, moments)))
        _set(prim, "physics:principalAxes", Sdf.ValueTypeNames.Quatf, Gf.Quatf(*map(float, quat)))
        if "NewtonMassAPI" in prim.GetAppliedSchemas():  # its newton:inertia tensor overrides the principal form
            t = physics.body_inertia[b][[0, 1, 2, 0, 0, 1], [0, 1, 2, 1, 2, 2]]  # xx, yy, zz, xy, xz, yz
            _set(prim, "newton:inertia", Sdf.ValueTypeNames.DoubleArray, [float(x) for x in t])
    stage.GetRootLayer().Save()

    act = Usd.Stage.CreateNew(str(out / "actuated.usda"))
    act.GetRootLayer().subLayerPaths.append("robot.usda")
    act.SetDefaultPrim(act.GetPrimAtPath(default.GetPath()))
    act.GetRootLayer().documentation = ("wresdyn calibrated robot with its drive path as Newton actuators "
                                        "(PD, delay, effort clamping) and the residual network")
    _copy_stage_metadata(base, act)
    scope = f"{default.GetPath()}/{ACTUATOR_SCOPE}"
    _set(act.DefinePrim(scope, "Scope"), "wresdyn:actuatorRateHz", Sdf.ValueTypeNames.Double, float(rate_hz))
    dt = 1.0 / rate_hz
    for i, (name, path) in enumerate(zip(robot.joint_names, joint_paths)):
        joint = act.OverridePrim(path)
        axis = "linear" if robot.is_prismatic()[i] else "angular"
        _set(joint, f"drive:{axis}:physics:stiffness", Sdf.ValueTypeNames.Float, 0.0)  # the actuator drives it
        _set(joint, f"drive:{axis}:physics:damping", Sdf.ValueTypeNames.Float, 0.0)
        prim = act.DefinePrim(f"{scope}/{name}", "NewtonActuator")
        is_servo = servo is not None and bool(servo.mask[i])
        schemas = [SERVO_SCHEMA if is_servo else "NewtonPDControlAPI"]
        prim.CreateRelationship("newton:targets").SetTargets([path])
        _set(prim, "newton:kp", Sdf.ValueTypeNames.Float, physics.kp[i])
        _set(prim, "newton:kd", Sdf.ValueTypeNames.Float, physics.kd[i])
        steps = int(round(physics.delay[i] / dt))
        if steps > 0:
            schemas.append("NewtonActuatorDelayAPI")
            _set(prim, "newton:delaySteps", Sdf.ValueTypeNames.Int, steps)
        if is_servo:
            schemas.append(_servo_prim(prim, physics, i))
        elif np.isfinite(physics.effort[i]):
            schemas.append("NewtonMaxEffortClampingAPI")
            _set(prim, "newton:maxEffort", Sdf.ValueTypeNames.Float, physics.effort[i])
        for s in schemas:
            prim.AddAppliedSchema(s)
    if residual is not None:
        prim = act.DefinePrim(f"{default.GetPath()}/{RESIDUAL_PRIM}", "Scope")
        prim.SetDocumentation("wresdyn residual: observation [q, qd, qdd, q_cmd] of wresdyn:joints (rad, rad/s, "
                              "rad/s^2, rad); output joint torque [N m] added to joint_f after the actuators "
                              "(wresdyn.export.residual_torque runs it)")
        _set(prim, "wresdyn:program", Sdf.ValueTypeNames.Asset, Sdf.AssetPath("residual.pt2"))
        _set(prim, "wresdyn:onnx", Sdf.ValueTypeNames.Asset, Sdf.AssetPath("residual.onnx"))
        _set(prim, "wresdyn:kind", Sdf.ValueTypeNames.Token, residual["kind"])
        _set(prim, "wresdyn:rateHz", Sdf.ValueTypeNames.Double, float(residual["rate_hz"]))
        by_name = dict(zip(robot.joint_names, joint_paths))
        prim.CreateRelationship("wresdyn:joints").SetTargets([by_name[n] for n in residual["joint_names"]])
    act.GetRootLayer().Save()


def _servo_prim(prim, physics, i: int) -> str:
    """Author servo joint ``i``'s drive on its actuator prim (``servo_actuator.py``'s ``WresdynServoControlAPI``:
    dead band, goal profile, back-EMF U / w0) and its clamp: ``NewtonDCMotorClampingAPI`` (stall torque U, no-load
    speed w0) or, without a torque-speed line, ``NewtonMaxEffortClampingAPI``; returns the clamp's schema."""
    from pxr import Sdf

    effort, w0 = float(physics.effort[i]), float(physics.noload_speed[i])
    _set(prim, "newton:servoDeadband", Sdf.ValueTypeNames.Float, physics.deadband[i])
    _set(prim, "newton:servoGoalAccel", Sdf.ValueTypeNames.Float, physics.goal_accel[i])
    _set(prim, "newton:servoBackEmf", Sdf.ValueTypeNames.Float, effort / w0 if w0 > 0 else 0.0)
    _set(prim, "newton:servoBacklash", Sdf.ValueTypeNames.Float, physics.backlash[i])
    _set(prim, "newton:servoEncoderOffset", Sdf.ValueTypeNames.Float, physics.encoder_offset[i])
    _set(prim, "newton:servoStartupTorque", Sdf.ValueTypeNames.Float, physics.startup_torque[i])
    if w0 > 0:
        _set(prim, "newton:saturationEffort", Sdf.ValueTypeNames.Float, effort)
        _set(prim, "newton:velocityLimit", Sdf.ValueTypeNames.Float, w0)
        _set(prim, "newton:maxMotorEffort", Sdf.ValueTypeNames.Float, effort)
        return "NewtonDCMotorClampingAPI"
    _set(prim, "newton:maxEffort", Sdf.ValueTypeNames.Float, effort)
    return "NewtonMaxEffortClampingAPI"


def _set(prim, name: str, type_name, value) -> None:
    attr = prim.GetAttribute(name)
    if not attr:
        attr = prim.CreateAttribute(name, type_name)
    if isinstance(value, (np.floating, float)):
        value = float(value)
    attr.Set(value)


def _write_servo_component(robot, out: Path) -> dict | None:
    """For a robot with servo drives: copy :mod:`~wresdyn.export.servo_actuator` and its USD schema plugin into
    ``out``; returns what ``export.json`` records of them (``None`` without servos)."""
    if getattr(robot, "servo", None) is None:
        return None
    component, schema = _SERVO_FILES
    shutil.copyfile(component, out / component.name)
    shutil.copytree(schema, out / schema.name, ignore=shutil.ignore_patterns("__pycache__"))
    return {"component": component.name, "schema": SERVO_SCHEMA, "schema_plugin": schema.name,
            "joints": [n for n, s in zip(robot.joint_names, robot.servo.mask) if s],
            "load": "import servo_actuator; servo_actuator.register() before the first USD stage is opened"}


def export_run(run: str | Path, out: str | Path | None = None, *, force: bool = False, physics_only: bool = False,
               data: str | None = None, gains=None) -> Path:
    """Export run folder ``run`` (``wresdyn fit``/``train``/``identify``) to ``out`` (default ``RUN/export``).

    Raises:
        ExportError: not a run, no residual (unless ``physics_only``), a delta-action residual, the robot file
            changed since the run's data were recorded, not a USD robot, ``out`` exists without ``force``.
    """

    run = Path(run)
    out = Path(out) if out is not None else run / "export"
    cfg_path, residual = open_run(run, out, force, physics_only)
    kappa = run_friction_kappa(run)
    data = data or json.loads(cfg_path.read_text()).get("data_path")
    if not data:
        raise ExportError(f"{run}: the run does not record its dataset; pass --data")
    ds = load_dataset(data)
    robot = dataset_robot(ds.robot_file, None, gains if gains is not None else ds.gains_config)
    if robot.source_sha256 != ds.robot_sha256:
        raise ExportError(f"{robot.source}: the robot file changed since the run's data were recorded (sha256 "
                          f"{robot.source_sha256[:12]} != {ds.robot_sha256[:12]}); the export would describe another robot")
    check_usd_robot(robot)
    if residual is not None and list(residual["joint_names"]) != list(robot.joint_names):
        raise ExportError(f"{run}: the residual's joints do not match {robot.source.name}'s")
    physics = run_physics(run, robot)
    if physics is None:  # a residual on the robot file's physics
        physics = PhysicalParams.nominal(robot)
    files = {}
    if residual is not None:
        files["residual.pt2"] = run / "policy.pt"
        if (run / "policy.onnx").is_file():
            files["residual.onnx"] = run / "policy.onnx"
    return write_export(out, robot, physics, ds.rate_hz, {"run": str(run), "dataset": str(data),
                                                           "gains": ds.gains_config}, residual, files,
                        friction_kappa=kappa)


def check_usd_robot(robot) -> None:
    """Raise :class:`ExportError` unless ``robot`` was loaded from USD, or from MJCF or URDF (converted first)."""
    why = None if is_usd(robot.source) else converter_missing(robot.source)
    if why:
        raise ExportError(why)


def write_export(out: str | Path, robot, physics, rate_hz: float, record: dict, residual: dict | None = None,
                 files: dict | None = None, *, friction_kappa: float | None = None) -> Path:
    """Write the export folder of ``physics`` on ``robot`` (module docstring) as ``out``, replacing what is there.

    Everything is written into a temporary folder beside ``out`` and swapped into place by two renames (the old
    folder aside, the new one in), then the old one is removed: a reader finds the old folder or the new one, never a
    half-written one, and a failure leaves ``out`` as it was.

    Args:
        out: The export folder.
        robot: The robot, loaded from a USD file (:func:`check_usd_robot`).
        physics: :class:`~wresdyn.sim.physics.PhysicalParams` to author.
        rate_hz: Actuator step rate [Hz] (the recording rate).
        record: Where the physics came from, written into ``export.json`` with the robot file, its sha256, the rate
            and the servo component.
        residual: ``residual.json`` of the run, or ``None`` for none.
        files: Files copied in, ``{name in out: source path}`` (the residual network).
        friction_kappa: The damper law's kappa [1/s] the physics were identified under (``None``: the default law);
            the friction amplitudes become Newton's joint friction, ``export.json``'s ``notes`` say so.
    """
    check_usd_robot(robot)
    out = Path(out)
    notes = usd_notes(robot, physics, friction_kappa)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        source = {"robot_file": str(robot.source), "robot_sha256": robot.source_sha256}
        if not is_usd(robot.source):  # the layers go over the converted file, kept in the folder
            robot, physics = converted_robot(robot, physics, tmp / "source")
            source["converted"] = str(Path(robot.source).resolve().relative_to(tmp.resolve()))
        write_layers(robot, physics, tmp, rate_hz, residual)
        physics.save(tmp / "physics.json")
        servo = _write_servo_component(robot, tmp)
        for name, src in (files or {}).items():
            shutil.copyfile(src, tmp / name)
        if residual is not None:
            (tmp / "residual.json").write_text(json.dumps(residual, indent=2))
        (tmp / "export.json").write_text(json.dumps({
            "format": "wresdyn.export/1", **record, **source, "rate_hz": rate_hz, "residual": residual is not None,
            "servo": servo, "friction_kappa": friction_kappa, "notes": notes}, indent=2))
        _swap(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def _swap(tmp: Path, out: Path) -> None:
    """Put the folder ``tmp`` in the place of ``out`` (absent or a folder); the old one is removed last."""
    if not out.exists():
        tmp.replace(out)
        return
    old = Path(tempfile.mkdtemp(prefix=f".{out.name}.old.", dir=out.parent))
    old.rmdir()
    out.replace(old)
    try:
        tmp.replace(out)
    except BaseException:
        old.replace(out)
        raise
    shutil.rmtree(old, ignore_errors=True)
