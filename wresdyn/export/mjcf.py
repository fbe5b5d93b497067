"""``wresdyn export RUN --format mjcf``: the calibrated robot as an MJCF file plain MuJoCo loads, and the residual.

The robot (from an MJCF, URDF or USD file) is rebuilt as a :class:`mujoco.MjSpec`
(:func:`~wresdyn.robot.mujoco_model.mujoco_spec`), its fields set to the run's identified
:class:`~wresdyn.sim.physics.PhysicalParams` and written by MuJoCo's own writer (``spec.to_xml()``). The folder:

=====================  ========================================================================================
``robot.xml``          the robot, time step 1 / rate (the recording's period, implicitfast), contacts off for a
                       fixed base (it hangs on a stand; a floating base gets the floor and collision shapes of
                       :func:`~wresdyn.robot.mujoco_model.mujoco_spec`). Per joint ``armature`` [kg m²],
                       ``damping`` [N m s/rad], ``frictionloss`` [N m]; per body mass [kg], CoM ``ipos`` [m] and
                       the inertia's principal moments and axes (``inertia``, ``iquat``); per joint a ``position``
                       actuator named after it: ``kp``, ``kv`` the identified gains, ``forcerange`` the effort
                       limit, ``delay`` the identified command delay [s] (MuJoCo's actuator delay, linear
                       interpolation between the stored commands, which is wresdyn's fractional delay exactly).
                       No visual meshes: the model carries the dynamics only.
``residual.onnx``      the residual network (``residual.json``: kind, joints, rate), with a residual;
``play_mujoco.py``     replays commands in MuJoCo with the residual and, on servo joints, the servo goal profile
                       and the servo law (mujoco, numpy, onnxruntime only); ``servo.json`` the servo joints' goal
                       acceleration [rad/s²] and law (:func:`servo_law`).
``mjcf_report.json``   what each identified term became, what has no MuJoCo counterpart, and the round trip on
                       held-out data: mean |q − q_recorded| of the wresdyn model and of the MJCF in MuJoCo.
``physics.json``       the identified parameters, ``export.json`` where they came from.
=====================  ========================================================================================

What changes: a run identified under the damper friction law (``friction_kappa``) gets its friction amplitudes
as MuJoCo's ``frictionloss`` with the friction constraint's ``solreffriction`` / ``solimpfriction`` set so that
MuJoCo's soft friction is that damper (:func:`damper_friction`); a run on the default soft friction law (fixed base)
gets per joint the ``solimpfriction`` that gives MuJoCo's friction regulariser, which MuJoCo scales by the exported
model's reference inertia, the replay solver's scale, the robot file's (:mod:`.mjcf_friction`); a servo joint
(:mod:`wresdyn.robot.servo`) becomes, in the plain MJCF, the closest plain actuator, a position actuator with
``kv = kd`` and the back-EMF ``U / w0`` in the joint damping, clamped at the stall torque U, without the dead band and
the goal-acceleration profile; its encoder offset o is the actuator's constant bias ``biasprm[0] = -kp o`` (the
drive ``kp (ctrl - q - o)``, exact); stiction, startup torque and backlash (MuJoCo has no gear play) have no
actuator. ``play_mujoco.py --servo servo.json`` applies the whole law instead (its
:class:`~wresdyn.export.play_mujoco.ServoLaw`: dead band, startup torque, backlash, offset, back-EMF and stiction,
the servo actuators silenced but still delaying the goal). The report names each of these; its round trip replays
with play_mujoco's servo law (``round_trip``), with the position actuators alone (``round_trip_position_actuators``)
and without the goal profile either (``round_trip_without_goal_profile``).
"""

from __future__ import annotations

import json
import math
import shutil
import tempfile
from pathlib import Path

import numpy as np

from ..data.dataset import load_dataset
from ..data.loading import dataset_robot
from ..evaluation.evaluate_run import run_friction_kappa
from ..learn.network_file import load_residual
from ..learn.runs import run_physics
from ..robot.mujoco_model import mujoco_body_names, mujoco_spec
from ..robot.servo import STARTUP_RAMP, STICTION_SPEED
from ..sim.physics import PhysicalParams
from ..sim.rollout import replay_trajectories
from . import play_mujoco
from .mjcf_friction import MJ_SOLREF_FRICTION, damper_friction, reference_inertia, soft_friction
from .run_folder import ExportError, open_run
from .usd import _swap, inertia_principal

__all__ = ["damper_friction", "export_mjcf", "mjcf_spec", "round_trip", "servo_law", "write_mjcf_export"]

ROUND_TRIP_TRAJECTORIES = 4
"""Held-out trajectories the export replays for its report (the first ones of the split)."""


def mjcf_spec(robot, physics, rate_hz: float, friction_kappa: float | None = None) -> tuple[object, list[str]]:
    """The :class:`mujoco.MjSpec` of ``robot`` with ``physics`` (module docstring) at time step ``1 / rate_hz``;
    returns it and the notes on what has no MuJoCo counterpart (one line each). ``friction_kappa``: the run's damper
    friction law, as the friction-loss constraint's parameters (:func:`damper_friction`)."""
    import mujoco

    physics.check(robot, "physics")
    spec = mujoco_spec(robot, 1.0 / rate_hz, "implicitfast", ground=robot.base == "floating")
    spec.modelname = f"{robot.source.stem}_calibrated"
    notes = []
    servo = getattr(robot, "servo", None)
    for i, name in enumerate(robot.joint_names):
        j = spec.joint(name)
        effort, damping = float(physics.effort[i]), float(physics.damping[i])
        if servo is not None and servo.mask[i]:
            w0 = float(physics.noload_speed[i])
            emf = effort / w0 if w0 > 0 else 0.0
            damping += emf  # the back-EMF U / w0 acts on the joint whether the PD saturates or not: not clamped
            dropped = [f"{f} {float(getattr(physics, f)[i]):.4g}" for f in ("deadband", "stiction", "startup_torque",
                                                                            "backlash", "load_friction")
                       if getattr(physics, f)[i] > 0]
            notes.append(f"{name}: servo drive as a position actuator (kp, kv = kd, force range +-{effort:.4g} N m) "
                         f"and its back-EMF U/w0 = {emf:.4g} N m s/rad in the joint damping"
                         + (f"; goal profile {float(physics.goal_accel[i]):.4g} rad/s^2 in servo.json (play_mujoco.py "
                            "applies it to the commands)" if physics.goal_accel[i] > 0 else "")
                         + f"; without a MuJoCo counterpart (play_mujoco.py --servo applies them): "
                           f"{', '.join(dropped) or 'nothing'}")
        j.armature = float(physics.armature[i])
        j.damping = [damping, *list(j.damping)[1:]]  # [linear, higher-order terms]
        j.frictionloss = float(physics.friction[i]) if friction_kappa != 0.0 else 0.0  # kappa 0: no friction
        act = spec.actuator(name)
        kv = float(physics.kd[i])
        act.set_to_position(kp=float(physics.kp[i]), kv=kv)
        if servo is not None and servo.mask[i] and physics.encoder_offset[i] != 0:  # kp (ctrl - q - o)
            act.biasprm = [-float(physics.kp[i]) * float(physics.encoder_offset[i]), *list(act.biasprm)[1:]]
        if np.isfinite(effort):
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.forcerange = [-effort, effort]
        delay = float(physics.delay[i])
        if delay > 0:
            act.delay = delay
            act.nsample = int(math.floor(delay * rate_hz + 1e-9)) + 2  # the two commands around t - delay
            act.interp = 1  # linear: (1 - a) c[k-m] + a c[k-m-1], wresdyn's fractional delay
    names = mujoco_body_names(robot.body_names)
    for b, name in enumerate(names):
        if not physics.body_mass[b] > 0:
            continue
        body = spec.body(name)
        moments, quat = inertia_principal(physics.body_inertia[b])
        moments = _triangle(moments, name, notes)
        body.mass, body.ipos = float(physics.body_mass[b]), np.asarray(physics.body_com[b], dtype=np.float64)
        body.inertia, body.iquat = np.maximum(moments, 1e-12), quat  # quat is (w, x, y, z), MuJoCo's order
        body.explicitinertial = True
    if friction_kappa:
        _damper_friction(spec, robot, friction_kappa, rate_hz, notes)
    elif friction_kappa is None and robot.base != "floating":
        _match_soft_friction(spec, robot, physics, rate_hz, notes)
    return spec, notes


def _damper_friction(spec, robot, friction_kappa: float, rate_hz: float, notes: list) -> None:
    """Set each joint's friction constraint to the damper law (:func:`damper_friction`, exact at the reference pose of
    the exported model) and say so in ``notes``."""
    m0, h_ii = reference_inertia(spec, robot.joint_names)
    ref, imp = damper_friction(friction_kappa, 1.0 / rate_hz, h_ii / m0)
    d = [float(x) for x in imp[0]]
    for i, name in enumerate(robot.joint_names):
        j = spec.joint(name)
        j.solref_friction, j.solimp_friction = [float(ref[0][i]), ref[1]], [d[i], d[i], *imp[2:]]
    notes.append(f"friction: identified under the damper law -clamp(kappa H_ii v, -mu, mu), kappa = "
                 f"{friction_kappa:g} /s; exported as MuJoCo's frictionloss mu with per joint solimpfriction d, "
                 "d/(1-d) = kappa dt H_ii/m0 (H_ii and m0 = 1/dof_invweight0 at the reference pose), and "
                 "solreffriction 2 dt/d 1: the same damper at the reference pose, its rate scaled by m0/H_ii "
                 "elsewhere; d per joint: " + ", ".join(f"{n} {x:.4f}" for n, x in zip(robot.joint_names, d)))


def _match_soft_friction(spec, robot, physics, rate_hz: float, notes: list) -> None:
    """Set each frictional joint's ``solimpfriction`` so that MuJoCo's soft friction, whose scale is the exported
    model's reference inertia, is the replay solver's, whose scale is the robot file's (:mod:`.mjcf_friction`); the
    replay solver drives a fixed base only (a floating base runs in Newton's MuJoCo solver, which recompiles it)."""
    joints = robot.joint_names
    m0_built = reference_inertia(mujoco_spec(robot, 1.0 / rate_hz, "implicitfast"), joints)[0]
    m0_export = reference_inertia(spec, joints)[0]
    imp, clipped = soft_friction(m0_built, m0_export)
    moved = []
    for i, name in enumerate(joints):
        if physics.friction[i] > 0:
            j = spec.joint(name)
            j.solref_friction, j.solimp_friction = list(MJ_SOLREF_FRICTION), imp[i].tolist()
            moved.append(f"{name} {m0_built[i] / m0_export[i]:.3g} -> {imp[i, 0]:.4f}"
                         + (" (clipped at MuJoCo's 0.9999)" if clipped[i] else ""))
    if moved:
        notes.append("friction: wresdyn's soft frictionloss scales its regulariser by each joint's reference inertia "
                     "of the robot file (fixed when the replay solver is built), MuJoCo by 1/dof_invweight0 of the "
                     "exported, identified model; per joint solimpfriction[0] = d with d/(1-d) = 9 m0_file/m0_export "
                     "(solimpfriction[1] 0.95 and solreffriction 0.02 1 kept: the same reference damping) makes "
                     "them one constraint. Per joint m0_file/m0_export -> d: " + ", ".join(moved))


def _triangle(moments: np.ndarray, body: str, notes: list) -> np.ndarray:
    """Principal moments [kg m^2] on the triangle inequality MuJoCo's compiler demands (each at most the sum of the
    other two), with a relative margin of ``_TRIANGLE_MARGIN`` that survives the MJCF's 6-digit numbers: an identified
    inertia can leave the set or end on its edge, since the fit bounds the moments one by one. The largest is lowered
    to the bound (the least change that a rigid body allows), and the change is named in ``notes``."""
    m = np.asarray(moments, dtype=np.float64).copy()
    k = int(np.argmax(m))
    bound = float(m.sum() - m[k]) * (1.0 - _TRIANGLE_MARGIN)
    if m[k] > bound:
        notes.append(f"{body}: identified principal inertia {np.array2string(m, precision=4)} kg m^2 at or over the "
                     f"triangle inequality's bound; its largest moment lowered to {bound:.6g} (a rigid body's bound)")
        m[k] = bound
    return m


_TRIANGLE_MARGIN = 1e-5
"""Relative margin under the triangle inequality's bound: twice the rounding of the MJCF's 6 significant digits."""


def export_mjcf(run: str | Path, out: str | Path | None = None, *, force: bool = False, physics_only: bool = False,
                data: str | None = None, gains=None, verify: bool = True) -> Path:
    """Export run folder ``run`` as MJCF into ``out`` (default ``RUN/export``; module docstring).

    ``verify``: replay the first held-out trajectories in wresdyn and in MuJoCo for the report's round trip.

    Raises:
        ExportError: not a run, no residual (unless ``physics_only``), a delta-action residual, the robot file
            changed since the run's data were recorded, ``out`` exists without ``force``.
    """
    run = Path(run)
    out = Path(out) if out is not None else run / "export"
    cfg_path, residual = open_run(run, out, force, physics_only)
    if residual is not None and not (run / "policy.onnx").is_file():
        raise ExportError(f"{run}: the run has no policy.onnx; MuJoCo runs the residual as ONNX")
    data = data or json.loads(cfg_path.read_text()).get("data_path")
    if not data:
        raise ExportError(f"{run}: the run does not record its dataset; pass --data")
    ds = load_dataset(data)
    robot = dataset_robot(ds.robot_file, None, gains if gains is not None else ds.gains_config)
    if robot.source_sha256 != ds.robot_sha256:
        raise ExportError(f"{robot.source}: the robot file changed since the run's data were recorded (sha256 "
                          f"{robot.source_sha256[:12]} != {ds.robot_sha256[:12]}); the export would describe another "
                          "robot")
    if residual is not None and list(residual["joint_names"]) != list(robot.joint_names):
        raise ExportError(f"{run}: the residual's joints do not match {robot.source.name}'s")
    physics = run_physics(run, robot)
    if physics is None:  # a residual on the robot file's physics
        physics = PhysicalParams.nominal(robot)
    kappa = run_friction_kappa(run)
    policy = None
    if residual is not None and verify:
        policy = load_residual(run / "policy.pt")
    held = ds.split("heldout")[:ROUND_TRIP_TRAJECTORIES] if verify and robot.base != "floating" else []
    files = {"residual.onnx": run / "policy.onnx"} if residual is not None else {}
    return write_mjcf_export(out, robot, physics, ds.rate_hz, {"run": str(run), "dataset": str(data),
                                                                "gains": ds.gains_config}, residual, files,
                             friction_kappa=kappa, heldout=held, policy=policy)


def servo_goal_accel(robot, physics) -> np.ndarray | None:
    """Goal acceleration [rad/s²] per joint for ``servo.json`` (0 on PD joints), ``None`` without a servo profile."""
    servo = getattr(robot, "servo", None)
    if servo is None or physics.goal_accel is None:
        return None
    accel = np.where(servo.mask, physics.goal_accel, 0.0)
    return accel if (accel > 0).any() else None


def servo_law(robot, physics) -> dict | None:
    """The servo joints' whole law for ``servo.json`` (:class:`~wresdyn.export.play_mujoco.ServoLaw`: per joint, in
    the actuators' order, SI units; 0 / mask 0 on PD joints), ``None`` for a robot without servo drives."""
    servo = getattr(robot, "servo", None)
    if servo is None:
        return None
    on = np.asarray(servo.mask, dtype=bool)
    law = {"mask": on.astype(float).tolist(), "ramp": STARTUP_RAMP, "stiction_speed": STICTION_SPEED}
    for f in ("kp", "kd", "effort", "damping", "friction", "deadband", "noload_speed", "startup_torque", "stiction",
              "backlash", "encoder_offset", "load_friction"):
        law[f] = np.where(on, np.nan_to_num(np.asarray(getattr(physics, f), dtype=np.float64), posinf=0.0),
                          0.0).tolist()
    return law


def round_trip(xml: str | Path, robot, physics, trajectories, rate_hz: float, policy=None, onnx=None,
               friction_kappa: float | None = None, goal_accel=None, reference=None, law=None) -> dict:
    """Replay ``trajectories`` open loop in wresdyn (``physics`` + ``policy``) and in MuJoCo (``xml`` + ``onnx``,
    with the servo goal profile ``goal_accel`` on the commands, through :mod:`play_mujoco`); returns mean
    |q − q_recorded| [rad] of each (``"wresdyn"``, ``"mujoco"``) and of the two replays against each other
    (``"between"``), over every joint and sample, and wresdyn's replays (``"q"``, list of (T, n) [rad]);
    ``reference``: such a ``"q"``, used instead of replaying in wresdyn again; ``law``: the servo drives' whole law
    (:func:`servo_law`) applied by play_mujoco's loop instead of the position actuators alone."""
    import mujoco

    ref = reference if reference is not None else replay_trajectories(
        robot, trajectories, rate_hz, policy, physics=physics, friction_kappa=friction_kappa)["residual"].q
    model = mujoco.MjModel.from_xml_path(str(xml))
    res = None if onnx is None else play_mujoco.Residual(str(onnx), 1.0 / rate_hz)
    mj = [play_mujoco.replay(model, t.q_cmd, t.q[0], t.qd[0], res, t.qdd[0], goal_accel, law)[0]
          for t in trajectories]
    err = lambda qs: float(np.mean(np.concatenate([np.abs(q - t.q) for q, t in zip(qs, trajectories)])))  # noqa: E731
    between = float(np.mean(np.concatenate([np.abs(a - b) for a, b in zip(mj, ref)])))
    return {"wresdyn": err(ref), "mujoco": err(mj), "between": between, "trajectories": len(trajectories),
            "samples": int(sum(len(t.q) for t in trajectories)), "q": ref}


def write_mjcf_export(out: str | Path, robot, physics, rate_hz: float, record: dict, residual: dict | None = None,
                      files: dict | None = None, *, friction_kappa: float | None = None, heldout=(),
                      policy=None) -> Path:
    """Write the MJCF export folder (module docstring) as ``out``, replacing what is there (written beside it and
    swapped in by renames: a failure leaves ``out`` as it was). ``heldout``: trajectories for the report's round
    trip (none: no round trip), replayed with ``policy`` in wresdyn and ``residual.onnx`` in MuJoCo."""
    out = Path(out)
    spec, notes = mjcf_spec(robot, physics, rate_hz, friction_kappa)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.", dir=out.parent))
    try:
        import mujoco

        (tmp / "robot.xml").write_text(spec.to_xml())
        try:
            mujoco.MjModel.from_xml_path(str(tmp / "robot.xml"))  # what a fresh process will load
        except ValueError as e:
            raise ExportError(f"{robot.source.name}: MuJoCo refuses the exported model: "
                              f"{' '.join(str(e).split())}") from None
        physics.save(tmp / "physics.json")
        for name, src in (files or {}).items():
            shutil.copyfile(src, tmp / name)
        if residual is not None:
            (tmp / "residual.json").write_text(json.dumps(residual, indent=2))
        shutil.copyfile(play_mujoco.__file__, tmp / "play_mujoco.py")
        accel, law = servo_goal_accel(robot, physics), servo_law(robot, physics)
        if law is not None:
            (tmp / "servo.json").write_text(json.dumps({
                "goal_accel": (accel if accel is not None else np.zeros(robot.n_dof)).tolist(),
                "joints": list(robot.joint_names), "law": law,
                "about": "goal-acceleration profile [rad/s^2] of the servo joints (0: none), applied to the commands, "
                         "and the servo law (play_mujoco.ServoLaw), applied by play_mujoco.py --servo"}, indent=2))
        report = {"format": "wresdyn.mjcf_report/1", "rate_hz": rate_hz, "friction_kappa": friction_kappa,
                  "notes": notes, "mapping": _mapping()}
        if len(heldout):
            onnx = tmp / "residual.onnx" if residual is not None else None
            trip = round_trip(tmp / "robot.xml", robot, physics, list(heldout), rate_hz, policy, onnx, friction_kappa,
                              accel, law=law)
            ref = trip.pop("q")
            report["round_trip"] = trip
            if law is not None:  # what the MJCF's position actuators lose without play_mujoco's servo loop
                keys = [("round_trip_position_actuators", accel)] + (
                    [("round_trip_without_goal_profile", None)] if accel is not None else [])
                for key, a in keys:
                    report[key] = round_trip(tmp / "robot.xml", robot, physics, list(heldout), rate_hz, policy, onnx,
                                             goal_accel=a, reference=ref)
                    report[key].pop("q")
        (tmp / "mjcf_report.json").write_text(json.dumps(report, indent=2))
        (tmp / "export.json").write_text(json.dumps({
            "format": "wresdyn.export/1", "kind": "mjcf", **record, "robot_file": str(robot.source),
            "robot_sha256": robot.source_sha256, "rate_hz": rate_hz, "residual": residual is not None}, indent=2))
        _swap(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out


def _mapping() -> dict:
    """Where each identified term went in ``robot.xml``."""
    return {"kp": "actuator/position kp [N m/rad]", "kd": "actuator/position kv [N m s/rad]",
            "effort": "actuator forcerange [N m]", "delay": "actuator delay [s] (interp linear, nsample)",
            "armature": "joint armature [kg m^2]", "damping": "joint damping [N m s/rad]",
            "friction": "joint frictionloss [N m] with solreffriction, solimpfriction (the replay's friction law)",
            "encoder_offset": "actuator biasprm[0] = -kp o [N m]",
            "backlash": "servo.json's law, applied by play_mujoco.py --servo (no gear play in MuJoCo)",
            "load_friction": "servo.json's law, applied by play_mujoco.py --servo (MuJoCo's frictionloss is constant)",
            "body_mass": "body inertial mass [kg]",
            "body_com": "body inertial pos [m]", "body_inertia": "body inertial diaginertia + quat [kg m^2]",
            "residual": "residual.onnx, applied through qfrc_applied by play_mujoco.py"}

