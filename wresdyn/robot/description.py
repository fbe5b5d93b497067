"""Robot loading: one robot file (USD, URDF or MJCF) -> one :class:`Robot` description.

Newton's importers are the single parser. The robot is loaded once into a single-world
:class:`newton.ModelBuilder`; :class:`Robot` keeps that builder (to replicate into N worlds) and a
plain-numpy view of everything the rest of wresdyn needs: the kinematic tree, inertias, actuated
joints with limits, PD gains, effort limits, armature and friction, and named frames (sites).

What Newton's importers leave out but the file states is read by :mod:`wresdyn.robot.file_import`; a gains config
(:mod:`wresdyn.robot.gains`) overrides drive and joint parameters by joint-name pattern. An effort limit that
nothing states keeps Newton's placeholder (1e6) and is refused by :meth:`Robot.check_effort` before any replay,
with the fix in the message (``effort = ...`` in a gains config).
The MuJoCo and Pinocchio models are built from this view (:mod:`wresdyn.robot.mujoco_model`,
:mod:`wresdyn.robot.pinocchio_model`), never through a lossy file round trip.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import RobotError
from ..paths import DEFAULT_ROBOT, file_sha256
from .contact import ContactSettings
from .file_import import SUFFIX_KIND, import_file, resolve_path, short_label
from .gains import apply_overrides, read_gains
from .packages import user_roots
from .servo import ServoDrives, attach_servo, read_servo

__all__ = ["Robot", "RobotError", "load_robot", "resolve_path", "DEFAULT_ROBOT", "PLACEHOLDER_EFFORT"]


_UNLIMITED = 1e5
"""Joint limits at or beyond this magnitude [rad or m] mean "no limit"."""
PLACEHOLDER_EFFORT = 1e5
"""An effort limit at or above this [N*m or N] (Newton's importers write 1e6 when a file states none; 0 and inf
are read as "none" too) is a placeholder, not a property of the robot: :meth:`Robot.check_effort` refuses it
unless a gains config sets it explicitly."""


@dataclass
class Robot:
    """A fixed- or floating-base articulated robot, as Newton imported it.

    Bodies are in Newton's order (parents before children); body 0 is the base. Every body has one
    parent joint; joint ``i`` connects body ``parent[i]`` (``-1``: world) to body ``i``. Only 1-DoF
    revolute and prismatic joints are actuated; fixed joints weld a body to its parent; the root joint is
    fixed (``base == "fixed"``) or free (``base == "floating"``).
    """

    def __reduce__(self):
        """Pickle as the :func:`load_robot` call that made it: the receiving process (a worker of a parallel
        ablation) loads the file again. The Newton builder itself holds Warp objects that do not pickle."""
        args = getattr(self, "_load_args", None)
        if args is None:
            raise TypeError("only a Robot made by load_robot can be pickled")
        return (_reload, (args, self.source_sha256))

    source: Path
    """Robot file the description was loaded from."""
    source_sha256: str
    """SHA-256 of the robot file's bytes."""
    base: str
    """``"fixed"`` (hung on a stand) or ``"floating"``."""
    builder: object = field(repr=False)
    """Single-world :class:`newton.ModelBuilder` holding this robot (gains overrides applied)."""

    body_names: list[str]
    """Body names (last path element), shape (n_bodies,)."""
    body_parent: np.ndarray
    """Parent body index, -1 for the world, shape (n_bodies,)."""
    joint_type: list[str]
    """Type of each body's parent joint: "revolute", "prismatic", "fixed" or "free", shape (n_bodies,)."""
    joint_X_p: np.ndarray
    """Joint frame in the parent body frame (or world), [x y z qx qy qz qw] [m], shape (n_bodies, 7)."""
    joint_X_c: np.ndarray
    """Joint frame in the child body frame, [x y z qx qy qz qw] [m], shape (n_bodies, 7)."""
    body_mass: np.ndarray
    """Body mass [kg], shape (n_bodies,)."""
    body_com: np.ndarray
    """Centre of mass in the body frame [m], shape (n_bodies, 3)."""
    body_inertia: np.ndarray
    """Rotational inertia about the centre of mass, in body-frame axes [kg*m^2], shape (n_bodies, 3, 3)."""

    joint_names: list[str]
    """Actuated joint names in DoF order, shape (n_dof,)."""
    dof_body: np.ndarray
    """Body moved by each actuated joint, shape (n_dof,)."""
    q_index: np.ndarray
    """Index of each actuated joint in a Newton world's ``joint_q``, shape (n_dof,)."""
    qd_index: np.ndarray
    """Index of each actuated joint in a Newton world's ``joint_qd`` / ``joint_f`` / targets, shape (n_dof,)."""
    axis: np.ndarray
    """Joint axis in the joint frame (unit vector), shape (n_dof, 3)."""
    lower: np.ndarray
    """Joint position lower limit [rad or m], shape (n_dof,)."""
    upper: np.ndarray
    """Joint position upper limit [rad or m], shape (n_dof,)."""
    kp: np.ndarray
    """PD stiffness [N*m/rad or N/m], shape (n_dof,)."""
    kd: np.ndarray
    """PD damping [N*m*s/rad or N*s/m], shape (n_dof,)."""
    effort: np.ndarray
    """Effort limit [N*m or N] (inf when unlimited), shape (n_dof,)."""
    armature: np.ndarray
    """Reflected rotor inertia added to the mass-matrix diagonal [kg*m^2 or kg], shape (n_dof,)."""
    friction: np.ndarray
    """Coulomb (dry) friction torque [N*m or N], shape (n_dof,)."""
    damping: np.ndarray
    """Passive viscous joint damping [N*m*s/rad or N*s/m], shape (n_dof,)."""

    frames: dict[str, tuple[int, np.ndarray]]
    """Named frames (sites): name -> (body index, [x y z qx qy qz qw] in the body frame)."""
    gravity: np.ndarray
    """Gravity vector [m/s^2], shape (3,)."""
    gains: dict | None = None
    """The gains config applied on top of the file (parsed TOML, ``{"joint": [...]}``), ``None`` when none."""
    gains_file: str | None = None
    """Path of the gains TOML as given (``None`` when none, or when given as a dict)."""
    effort_given: np.ndarray | None = None
    """True where the gains config sets the joint's effort limit explicitly, shape (n_dof,) (``None``: nowhere)."""
    servo: ServoDrives | None = None
    """The joints whose drive is a smart servo and their servo parameters (:mod:`wresdyn.robot.servo`; gains config
    ``drive = "servo"``); ``None``: every drive is PD."""

    @property
    def n_dof(self) -> int:
        return len(self.joint_names)

    @property
    def n_bodies(self) -> int:
        return len(self.body_names)

    @property
    def q0(self) -> np.ndarray:
        """Neutral joint positions [rad or m]: 0 clipped into the limits, shape (n_dof,)."""
        return np.clip(np.zeros(self.n_dof), self.lower, self.upper)

    def is_prismatic(self) -> np.ndarray:
        """Boolean mask of prismatic DoF, shape (n_dof,)."""
        return np.array([self.joint_type[b] == "prismatic" for b in self.dof_body], dtype=bool)

    def placeholder_effort(self) -> list[str]:
        """Joints whose effort limit is a placeholder (at or above :data:`PLACEHOLDER_EFFORT`, or none at all)
        that no gains config set explicitly."""
        given = self.effort_given if self.effort_given is not None else np.zeros(self.n_dof, dtype=bool)
        return [n for n, e, g in zip(self.joint_names, self.effort, given) if not e < PLACEHOLDER_EFFORT and not g]

    def missing_gains(self) -> list[str]:
        """Actuated joints without PD stiffness (``kp`` zero or absent in the file and in the gains config): a
        position replay cannot drive them."""
        return [n for n, k in zip(self.joint_names, self.kp) if not k > 0.0]

    def check_gains(self) -> None:
        """Raise :class:`RobotError` if any actuated joint has no PD stiffness (:meth:`missing_gains`)."""
        self._refuse(self.missing_gains(), [])

    def check_effort(self) -> None:
        """Raise :class:`RobotError` if any actuated joint has a placeholder effort limit (see
        :meth:`placeholder_effort`): the real robot's torque saturation and the mismatch's friction (a fraction of
        the effort limit) would be made up."""
        self._refuse([], self.placeholder_effort())

    def check_replay(self) -> None:
        """Everything a replay or a fit needs from the robot: PD gains (:meth:`check_gains`) and stated effort
        limits (:meth:`check_effort`), refused together in one line that names the joints. Position limits are not
        required: a continuous joint is excited over +-pi."""
        self._refuse(self.missing_gains(), self.placeholder_effort())

    def _refuse(self, no_gains: list[str], no_effort: list[str]) -> None:
        """One :class:`RobotError` line naming the joints without gains and without an effort limit, with the gains
        config that supplies them (a pattern for one joint, ``*`` for several)."""
        if not no_gains and not no_effort:
            return

        def names(bad):
            return f"{', '.join(bad[:4])}{', ...' if len(bad) > 4 else ''}"

        parts, keys = [], []
        if no_gains:
            parts.append(f"{len(no_gains)} of {self.n_dof} joints have no PD gains ({names(no_gains)})")
            keys.append("kp = 100.0 kd = 5.0")
        if no_effort:
            parts.append(f"{len(no_effort)} of {self.n_dof} joints have no effort limit in the file, only the "
                         f"importer's placeholder ({names(no_effort)})")
            keys.append("effort = 3.0 (N*m)")
        bad = set(no_gains) | set(no_effort)
        match = next(iter(bad)) if len(bad) == 1 else "*"
        raise RobotError(f"{self.source}: {' and '.join(parts)}; set them in a gains config passed with --gains "
                         f"FILE.toml, e.g. [[joint]] match = \"{match}\" {' '.join(keys)}")

    def gains_record(self) -> dict | None:
        """The gains config as a dataset stores it: ``{"file": path or None, "config": parsed TOML}``, or ``None``
        when the robot file is used as it is."""
        if self.gains is None:
            return None
        return {"file": self.gains_file, "config": copy.deepcopy(self.gains)}

    def build_model(self, num_worlds: int = 1, device: str | None = None, requires_grad: bool = False,
                    ground: bool = False, contact=None):
        """Finalize a Newton :class:`~newton.Model` with ``num_worlds`` copies of the robot.

        Args:
            num_worlds: Number of independent worlds (one robot each).
            device: Warp device (``"cpu"``, ``"cuda:0"``); ``None`` takes Warp's default.
            requires_grad: Allocate gradients for Warp autodiff.
            ground: Add a floor through the origin, normal to the up axis: one plane shared by every world (Newton's
                global world -1; the worlds' robots never touch each other), and give every collision shape of
                the robot the material of ``contact``.
            contact: :class:`~wresdyn.robot.contact.ContactSettings` of the floor and the robot's shapes (default
                ``ContactSettings()``); only with ``ground``.
        """
        import newton

        scene = newton.ModelBuilder(up_axis=self.builder.up_axis, gravity=tuple(float(g) for g in self.gravity))
        scene.replicate(self.builder, num_worlds)
        if ground:
            c = contact or ContactSettings()
            material = {"shape_material_mu": c.friction, "shape_material_mu_torsional": c.torsional_friction,
                        "shape_material_mu_rolling": c.rolling_friction, "shape_material_ke": c.ke,
                        "shape_material_kd": c.kd, "shape_margin": c.margin, "shape_gap": c.gap}
            collide = int(newton.ShapeFlags.COLLIDE_SHAPES)
            for name, value in material.items():
                values = getattr(scene, name)  # read after replicate: it may replace the lists
                for s in range(scene.shape_count):
                    if int(scene.shape_flags[s]) & collide:
                        values[s] = value
            cfg = newton.ModelBuilder.ShapeConfig(mu=c.friction, mu_torsional=c.torsional_friction,
                                                  mu_rolling=c.rolling_friction, ke=c.ke, kd=c.kd, margin=c.margin,
                                                  gap=c.gap)
            scene.add_ground_plane(cfg=cfg)
        elif contact is not None:
            raise ValueError("contact settings without a ground: pass ground=True")
        model = scene.finalize(device=device, requires_grad=requires_grad)
        if self.servo is not None:
            attach_servo(model, self.servo, self.qd_index, num_worlds)
        return model



def load_robot(path: str | Path, gains: str | Path | dict | None = None, base: str = "fixed",
               package_path: list[str] | str | None = None) -> Robot:
    """Load a robot file into a :class:`Robot`.

    Args:
        path: USD (``.usd/.usda/.usdc``), URDF (``.urdf``) or MJCF (``.xml``) file, or ``newton:NAME`` for an
            asset bundled with newton.
        gains: Optional overrides by joint-name pattern, a TOML file or the parsed dict
            (see :func:`~wresdyn.robot.gains.apply_overrides`); kept on the robot (:attr:`Robot.gains`) so a dataset
            can store it.
        base: ``"fixed"`` (the robot hangs on a stand, as in data collection) or ``"floating"``.
        package_path: Folders that hold the ROS packages a URDF's ``package://`` URIs name
            (:mod:`wresdyn.robot.packages`); default: the command line's ``--package-path``.

    Raises:
        RobotError: one-line message naming the file and the problem.
    """
    import warp as wp

    # before newton initialises warp: no banner and no per-module load messages
    wp.config.quiet = True
    wp.config.log_level = max(wp.config.log_level, wp.LOG_WARNING)
    import newton

    path = resolve_path(path)
    if base not in ("fixed", "floating"):
        raise RobotError(f"{path}: base must be 'fixed' or 'floating', not {base!r}")
    if not path.is_file():
        raise RobotError(f"{path}: robot file not found")
    kind = SUFFIX_KIND.get(path.suffix.lower())
    if kind is None:
        raise RobotError(f"{path}: unknown robot file type {path.suffix!r} (expected .usd/.usda/.usdc, .urdf or .xml)")
    roots = user_roots() if package_path is None else package_path
    builder = newton.ModelBuilder()
    try:
        import_file(builder, path, kind, floating=(base == "floating"), package_path=roots)
    except RobotError:
        raise
    except Exception as e:  # importers raise many types on malformed input; report one line
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise RobotError(f"{path}: cannot parse {kind.upper()} file: {msg}") from None
    if builder.joint_count == 0 or builder.body_count == 0:
        raise RobotError(f"{path}: no articulation found (no bodies connected by joints)")
    config, gains_file, effort_dofs = None, None, set()
    if gains is not None:
        config, gains_file = read_gains(gains)
        effort_dofs = apply_overrides(builder, config, source=path, where=gains_file or "gains config")
    robot = _describe(builder, path, base)
    robot.gains, robot.gains_file = config, gains_file
    robot.effort_given = np.array([int(d) in effort_dofs for d in robot.qd_index], dtype=bool)
    robot.servo = read_servo(config, robot.joint_names, robot.effort, gains_file or "gains config")
    robot._load_args = (str(path), gains if isinstance(gains, dict) or gains is None else str(gains), base,
                        [str(r) for r in roots] if isinstance(roots, list) else roots)
    return robot


def _reload(args: tuple, sha256: str) -> Robot:
    """Unpickle a :class:`Robot`: load the file again and check it is still the same file."""
    robot = load_robot(*args)
    if robot.source_sha256 != sha256:
        raise RobotError(f"{robot.source}: the robot file changed since it was loaded in the parent process")
    return robot


def _describe(builder, path: Path, base: str) -> Robot:
    import newton

    JT = newton.JointType
    names = {JT.REVOLUTE: "revolute", JT.PRISMATIC: "prismatic", JT.FIXED: "fixed", JT.FREE: "free"}
    nb = builder.body_count
    jt = [int(t) for t in builder.joint_type]
    child = list(builder.joint_child)
    parent = list(builder.joint_parent)
    if sorted(child) != list(range(nb)):
        raise RobotError(f"{path}: not a tree: each body needs exactly one parent joint")
    roots = [j for j in range(len(jt)) if parent[j] == -1]
    if len(roots) != 1:
        raise RobotError(f"{path}: expected one articulation, found {len(roots)} root bodies")
    for j, t in enumerate(jt):
        if t not in names:
            raise RobotError(
                f"{path}: unsupported joint type {JT(t).name} at {builder.joint_label[j]!r} "
                "(wresdyn supports revolute, prismatic and fixed joints on a fixed or free base)"
            )
        if t == JT.FREE and parent[j] != -1:
            raise RobotError(f"{path}: free joint {builder.joint_label[j]!r} is not the root joint")
    by_child = {c: j for j, c in enumerate(child)}
    order = [by_child[b] for b in range(nb)]
    for b in range(nb):
        p = parent[by_child[b]]
        if p >= b:
            raise RobotError(f"{path}: bodies are not ordered parents-first")

    qd_start = list(builder.joint_qd_start)
    q_start = list(builder.joint_q_start)
    dof_joint = [(j, qd_start[j]) for j in order if jt[j] in (JT.REVOLUTE, JT.PRISMATIC)]
    if not dof_joint:
        raise RobotError(f"{path}: no actuated revolute or prismatic joint")
    dofs = [d for _, d in dof_joint]

    def arr(name, idx=dofs):
        return np.asarray(getattr(builder, name), dtype=np.float64)[idx]

    frames = {}
    for s, label in enumerate(builder.shape_label):
        flags = int(builder.shape_flags[s])
        if flags & int(newton.ShapeFlags.SITE) and builder.shape_body[s] >= 0:
            frames[short_label(label)] = (int(builder.shape_body[s]), np.asarray(builder.shape_transform[s], dtype=np.float64))

    lower, upper = arr("joint_limit_lower"), arr("joint_limit_upper")
    # importers write +-1e6 (Newton's default) for an unlimited joint
    lower[lower <= -_UNLIMITED], upper[upper >= _UNLIMITED] = -np.inf, np.inf
    effort = arr("joint_effort_limit")
    effort[~(effort > 0)] = np.inf  # importers write 0 or inf for "no limit"
    return Robot(
        source=path,
        source_sha256=file_sha256(path),
        base=base,
        builder=builder,
        body_names=[short_label(builder.body_label[b]) for b in range(nb)],
        body_parent=np.array([parent[by_child[b]] for b in range(nb)], dtype=np.int64),
        joint_type=[names[JT(jt[by_child[b]])] for b in range(nb)],
        joint_X_p=np.array([builder.joint_X_p[by_child[b]] for b in range(nb)], dtype=np.float64),
        joint_X_c=np.array([builder.joint_X_c[by_child[b]] for b in range(nb)], dtype=np.float64),
        body_mass=np.asarray(builder.body_mass, dtype=np.float64),
        body_com=np.asarray(builder.body_com, dtype=np.float64).reshape(nb, 3),
        body_inertia=np.asarray(builder.body_inertia, dtype=np.float64).reshape(nb, 3, 3),
        joint_names=[short_label(builder.joint_label[j]) for j, _ in dof_joint],
        dof_body=np.array([child[j] for j, _ in dof_joint], dtype=np.int64),
        q_index=np.array([q_start[j] for j, _ in dof_joint], dtype=np.int64),
        qd_index=np.array(dofs, dtype=np.int64),
        axis=np.asarray(builder.joint_axis, dtype=np.float64)[dofs].reshape(-1, 3),
        lower=lower,
        upper=upper,
        kp=arr("joint_target_ke"),
        kd=arr("joint_target_kd"),
        effort=effort,
        armature=arr("joint_armature"),
        friction=arr("joint_friction"),
        damping=arr("joint_damping") if hasattr(builder, "joint_damping") else np.zeros(len(dofs)),
        frames=frames,
        gravity=np.array([0.0, 0.0, -9.81]) if builder.up_axis == newton.Axis.Z else np.array([0.0, -9.81, 0.0]),
    )
