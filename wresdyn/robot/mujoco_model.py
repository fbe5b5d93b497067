"""The same robot as a MuJoCo model, built with ``mujoco.MjSpec`` from a :class:`~wresdyn.robot.description.Robot`.

Bodies, inertias, joint axes, limits, armature, damping and dry friction are copied field by field;
PD drives become MuJoCo position actuators (``kp``, ``kv``) with the effort limit as force range.
By default contacts are disabled: the robot hangs on a stand and the Newton replay has no contacts either.
With ``ground=True`` the robot gets a floor and its collision geometry, written as Newton's ``SolverMuJoCo``
writes them (:mod:`wresdyn.robot.ground`): the same geoms, materials and solver options, so the MuJoCo C robot
and Newton's stand on the same contact. :func:`free_to_mujoco` / :func:`free_from_mujoco` convert the free
joint between Newton's convention and MuJoCo's.
:func:`mujoco_spec` gives the uncompiled spec. The integrator is ``implicitfast``, MuJoCo's recommended default, which treats the actuator's
velocity gain implicitly (stable with high drive damping).
"""

from __future__ import annotations

import numpy as np

from .contact import ContactSettings
from .description import Robot
from .ground import collision_shapes

__all__ = ["build_mujoco", "mujoco_spec", "mujoco_body_names", "free_from_mujoco", "free_to_mujoco",
           "quat_xyzw_to_wxyz"]

MUJOCO_WORLD = "world"
"""The name MuJoCo reserves for its world body; a robot body of that name (a URDF's fixed ``world`` link, as in the
UR5 and Panda files of example-robot-data) is renamed in the MuJoCo model."""


def quat_xyzw_to_wxyz(q: np.ndarray) -> np.ndarray:
    """Newton/Warp quaternion [x y z w] -> MuJoCo quaternion [w x y z]."""
    q = np.asarray(q, dtype=np.float64)
    return np.concatenate([q[..., 3:4], q[..., :3]], axis=-1)


def _tf_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Compose transforms [p, q_xyzw]: a * b."""
    from scipy.spatial.transform import Rotation as R

    ra, rb = R.from_quat(a[3:]), R.from_quat(b[3:])
    return np.concatenate([a[:3] + ra.apply(b[:3]), (ra * rb).as_quat()])


def _tf_inv(a: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation as R

    r = R.from_quat(a[3:]).inv()
    return np.concatenate([-r.apply(a[:3]), r.as_quat()])


def mujoco_body_names(names: list[str]) -> list[str]:
    """The robot's body names as the MuJoCo model carries them: each as it is, except a body named ``world`` (MuJoCo
    refuses a second body of its world's name), which becomes ``world_link`` (``world_link_1``, ... if that name is
    taken), so every name stays unique and the rest keep the robot's."""
    taken = set(names)
    out = []
    for name in names:
        if name == MUJOCO_WORLD:
            new, k = f"{name}_link", 0
            while new in taken:
                k += 1
                new = f"{name}_link_{k}"
            taken.add(new)
            name = new
        out.append(name)
    return out


def build_mujoco(robot: Robot, dt: float = 0.002, integrator: str = "implicitfast", ground: bool = False,
                 contact=None):
    """Build a :class:`mujoco.MjModel` of ``robot``: :func:`mujoco_spec` compiled (the arguments are its)."""
    return mujoco_spec(robot, dt, integrator, ground, contact).compile()


def mujoco_spec(robot: Robot, dt: float = 0.002, integrator: str = "implicitfast", ground: bool = False,
                contact=None):
    """The :class:`mujoco.MjSpec` of ``robot`` (uncompiled: a peer tool may edit it, e.g. ``mujoco.sysid``).

    Args:
        robot: The robot description.
        dt: Time step [s].
        integrator: MuJoCo integrator name (``"implicitfast"``, ``"Euler"``, ``"RK4"``, ``"implicit"``).
        ground: Add a floor (a plane through the origin, normal to the up axis) and the robot's collision shapes
            (:func:`~wresdyn.robot.ground.collision_shapes`), contacts on: each shape collides with the floor
            only, as Newton's importers leave self-collisions off.
        contact: :class:`~wresdyn.robot.ground.ContactSettings` (default ``ContactSettings()``); only with
            ``ground``.

    Returns:
        ``mujoco.MjSpec`` whose ``nu`` actuators and dof order are ``robot.joint_names`` (plus the free
        joint's 6 DoF first for a floating base: MuJoCo dof ``6 + i`` and qpos ``7 + i`` are joint ``i``), each
        actuator named after its joint.
    """
    import mujoco
    from scipy.spatial.transform import Rotation as R

    spec = mujoco.MjSpec()
    spec.modelname = robot.source.stem
    spec.option.timestep = dt
    spec.option.gravity = robot.gravity
    spec.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{integrator.upper()}")
    spec.compiler.autolimits = True
    spec.compiler.degree = False
    shapes: dict[int, list] = {}
    if ground:
        shapes = _add_ground(spec, robot, contact)
    elif contact is not None:
        raise ValueError("contact settings without a ground: pass ground=True")
    else:
        spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT

    dof_of_body = {int(b): i for i, b in enumerate(robot.dof_body)}
    body_names = mujoco_body_names(robot.body_names)
    sbodies = []
    for b in range(robot.n_bodies):
        parent = spec.worldbody if robot.body_parent[b] < 0 else sbodies[robot.body_parent[b]]
        # body frame in the parent frame at q = 0: X_p * inv(X_c)
        x = _tf_mul(robot.joint_X_p[b], _tf_inv(robot.joint_X_c[b]))
        body = parent.add_body(name=body_names[b], pos=x[:3], quat=quat_xyzw_to_wxyz(x[3:]))
        sbodies.append(body)
        m = float(robot.body_mass[b])
        if m > 0.0:
            body.mass = m
            body.ipos = robot.body_com[b]
            # diagonalise the inertia so MuJoCo keeps it exactly (principal frame in iquat)
            inertia = 0.5 * (robot.body_inertia[b] + robot.body_inertia[b].T)
            w, v = np.linalg.eigh(inertia)
            if np.linalg.det(v) < 0:
                v[:, 0] = -v[:, 0]
            body.inertia = np.maximum(w, 1e-12)
            body.iquat = quat_xyzw_to_wxyz(R.from_matrix(v).as_quat())
            body.explicitinertial = True
        jt = robot.joint_type[b]
        xc = robot.joint_X_c[b]
        if jt == "free":
            body.add_freejoint(name=body_names[b] + "_free")
        elif jt in ("revolute", "prismatic"):
            i = dof_of_body[b]
            axis = R.from_quat(xc[3:]).apply(robot.axis[i])
            j = body.add_joint(
                name=robot.joint_names[i],
                type=mujoco.mjtJoint.mjJNT_HINGE if jt == "revolute" else mujoco.mjtJoint.mjJNT_SLIDE,
                pos=xc[:3],
                axis=axis,
                armature=float(robot.armature[i]),
                damping=float(robot.damping[i]),
                frictionloss=float(robot.friction[i]),
            )
            if np.isfinite(robot.lower[i]) and np.isfinite(robot.upper[i]) and robot.lower[i] < robot.upper[i]:
                j.limited = mujoco.mjtLimited.mjLIMITED_TRUE
                j.range = [robot.lower[i], robot.upper[i]]
        for name, (fb, tf) in robot.frames.items():
            if fb == b:
                body.add_site(name=name, pos=tf[:3], quat=quat_xyzw_to_wxyz(tf[3:]))
        for geom in shapes.get(b, []):
            body.add_geom(**geom)
    for i, name in enumerate(robot.joint_names):
        act = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        act.set_to_position(kp=float(robot.kp[i]), kv=float(robot.kd[i]))
        if np.isfinite(robot.effort[i]):
            act.forcelimited = mujoco.mjtLimited.mjLIMITED_TRUE
            act.forcerange = [-robot.effort[i], robot.effort[i]]
    return spec


_GEOM = {"box": "mjGEOM_BOX", "sphere": "mjGEOM_SPHERE", "capsule": "mjGEOM_CAPSULE", "cylinder": "mjGEOM_CYLINDER",
         "ellipsoid": "mjGEOM_ELLIPSOID"}


def _add_ground(spec, robot: Robot, contact) -> dict[int, list]:
    """The floor and the solver options on ``spec``, and the robot's collision geoms per body (keyword arguments
    of ``add_geom``), each field as Newton's ``SolverMuJoCo`` writes it (its geom names included)."""
    import mujoco

    c = contact or ContactSettings()
    spec.option.cone = getattr(mujoco.mjtCone, f"mjCONE_{c.cone.upper()}")
    spec.option.solver = getattr(mujoco.mjtSolver, f"mjSOL_{c.solver.upper()}")
    spec.option.iterations, spec.option.ls_iterations, spec.option.impratio = c.iterations, c.ls_iterations, c.impratio
    spec.option.disableflags |= mujoco.mjtDisableBit.mjDSBL_MULTICCD  # SolverMuJoCo's enable_multiccd=False
    # the geoms carry no mass: every body's inertia is the robot's, copied (a body without one stays massless)
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    material = {"friction": [c.friction, c.torsional_friction, c.rolling_friction], "solref": list(c.solref),
                "solimp": list(c.solimp), "condim": c.condim, "margin": c.margin, "gap": c.gap}
    # MuJoCo collides two geoms when contype of one meets conaffinity of the other: the floor meets every robot
    # geom, robot geoms never meet each other (SolverMuJoCo's masks for a robot without self-collisions)
    up = -np.asarray(robot.gravity, dtype=np.float64) / np.linalg.norm(robot.gravity)
    floor_quat = quat_xyzw_to_wxyz(_quat_between(np.array([0.0, 0.0, 1.0]), up))
    spec.worldbody.add_geom(name=f"ground_plane_{robot.builder.shape_count}", type=mujoco.mjtGeom.mjGEOM_PLANE,
                            size=[5.0, 5.0, 5.0], quat=floor_quat, contype=1, conaffinity=0, **material)
    geoms: dict[int, list] = {}
    for sh in collision_shapes(robot):
        size = sh.size.copy()
        size[size == 0.0] = size[size > 0.0][0]  # MuJoCo reads only the sizes a type uses; SolverMuJoCo fills the rest
        geoms.setdefault(sh.body, []).append({
            "name": f"{sh.label}_{sh.index}", "type": getattr(mujoco.mjtGeom, _GEOM[sh.kind]), "size": size,
            "pos": sh.transform[:3], "quat": quat_xyzw_to_wxyz(sh.transform[3:]), "contype": 0, "conaffinity": 1,
            **material})
    return geoms


def _quat_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Shortest rotation [x y z w] taking unit vector ``a`` to ``b``."""
    from scipy.spatial.transform import Rotation as R

    if np.allclose(a, b):
        return np.array([0.0, 0.0, 0.0, 1.0])
    return R.align_vectors(b[None], a[None])[0].as_quat()


def free_to_mujoco(robot: Robot, base_pose: np.ndarray, base_twist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Newton's free joint -> MuJoCo's: ``(qpos[..., :7], qvel[..., :6])``; one state (7,), (6,) or a batch
    (..., 7), (..., 6).

    Newton (:mod:`wresdyn.robot.ground`): pose [x y z qx qy qz qw], twist [centre-of-mass velocity, angular
    velocity], world axes. MuJoCo: qpos [x y z qw qx qy qz] of the body frame; qvel [velocity of the body
    frame's origin in world axes, angular velocity in body axes].
    """
    from scipy.spatial.transform import Rotation as R

    pose, twist = np.asarray(base_pose, dtype=np.float64), np.asarray(base_twist, dtype=np.float64)
    shape = pose.shape[:-1]
    pose, twist = pose.reshape(-1, 7), twist.reshape(-1, 6)
    rot = R.from_quat(pose[:, 3:])
    w = twist[:, 3:]
    v_origin = twist[:, :3] - np.cross(w, rot.apply(robot.body_com[0]))
    qpos = np.concatenate([pose[:, :3], quat_xyzw_to_wxyz(rot.as_quat())], axis=-1)
    qvel = np.concatenate([v_origin, rot.inv().apply(w)], axis=-1)
    return qpos.reshape(*shape, 7), qvel.reshape(*shape, 6)


def free_from_mujoco(robot: Robot, qpos: np.ndarray, qvel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MuJoCo's free joint ``(qpos[..., :7], qvel[..., :6])`` -> Newton's ``(base_pose, base_twist)`` (the inverse
    of :func:`free_to_mujoco`; one state or a batch)."""
    from scipy.spatial.transform import Rotation as R

    qpos, qvel = np.asarray(qpos, dtype=np.float64), np.asarray(qvel, dtype=np.float64)
    shape = qpos.shape[:-1]
    qpos, qvel = qpos.reshape(-1, qpos.shape[-1])[:, :7], qvel.reshape(-1, qvel.shape[-1])[:, :6]
    rot = R.from_quat(qpos[:, 3:7], scalar_first=True)
    w = rot.apply(qvel[:, 3:6])
    v_com = qvel[:, :3] + np.cross(w, rot.apply(robot.body_com[0]))
    pose = np.concatenate([qpos[:, :3], rot.as_quat()], axis=-1)
    return pose.reshape(*shape, 7), np.concatenate([v_com, w], axis=-1).reshape(*shape, 6)


def mujoco_replay(mj_model, q_cmd: np.ndarray, q0: np.ndarray, qd0: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop PD replay in MuJoCo C (fixed base), command k held during step k.

    Args:
        mj_model: Model from :func:`build_mujoco`.
        q_cmd: Commanded joint positions [rad], shape (T, n_dof).
        q0, qd0: Initial joint positions [rad] and velocities [rad/s], shape (n_dof,).

    Returns:
        ``(q, qd)`` of shape (T + 1, n_dof).
    """
    import mujoco

    d = mujoco.MjData(mj_model)
    d.qpos[:] = q0
    d.qvel[:] = 0.0 if qd0 is None else qd0
    t_len = len(q_cmd)
    q = np.empty((t_len + 1, mj_model.nq))
    qd = np.empty((t_len + 1, mj_model.nv))
    q[0], qd[0] = d.qpos, d.qvel
    for k in range(t_len):
        d.ctrl[:] = q_cmd[k]
        mujoco.mj_step(mj_model, d)
        q[k + 1], qd[k + 1] = d.qpos, d.qvel
    return q, qd
