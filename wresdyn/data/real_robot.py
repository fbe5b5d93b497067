"""The "real robot": MuJoCo C running a perturbed copy of the robot, recorded under PD like hardware.

The nominal model comes from :func:`wresdyn.robot.mujoco_model.build_mujoco`; a
:class:`~wresdyn.data.mismatch.Mismatch` then changes its fields (Coulomb friction, viscous damping, armature,
link mass / centre of mass / inertia, PD gains, torque limits), adds an actuator delay (a FIFO of commands at the
physics step) and degrades the recorded joint states (encoder noise and quantisation). It integrates with ``implicitfast`` at its own, finer
``substep``: a different "physical" robot from the Newton replay, as real hardware is. With every
mismatch off and ``substep`` equal to the recording step it is exactly :func:`~wresdyn.robot.mujoco_model.mujoco_replay`.

A fixed-base robot records on a stand (:meth:`RealRobot.record`, :func:`collect`). A floating-base robot stands on
a floor (:func:`~wresdyn.robot.mujoco_model.build_mujoco` with ``ground=True``, the contact of
:class:`~wresdyn.robot.ground.ContactSettings` with the mismatch's floor friction and softness,
:func:`~wresdyn.data.mismatch.floor_contact`) and is driven step by step, as a deployed skill drives hardware:
:meth:`RealRobot.reset` to a :class:`~wresdyn.robot.ground.FloatingState`, :meth:`RealRobot.step` under PD
commands, with the same mismatch (physics, delay, saturation, sensors) as a recording.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from pathlib import Path

import numpy as np

from ..errors import SimulationDiverged
from ..paths import REPO
from ..progress import bar
from ..robot.description import Robot, RobotError
from ..robot.ground import FloatingState, check_floating
from ..robot.mujoco_model import build_mujoco, free_from_mujoco, free_to_mujoco
from ..robot.physical import SERVO_FIELDS, PhysicalParams
from ..robot.servo import STARTUP_RAMP, GoalProfile, friction_bound, play
from . import excitation as ex
from .dataset import SPLITS, Dataset, Trajectory, derive_qdd
from .mismatch import Mismatch, MismatchError, floor_contact, perturb_mujoco
from .probe import PROBE_FAMILY, SaturationProbe, saturation_probe

__all__ = ["RealRobot", "SPAWN_KEYS", "PROBE_SPAWN_KEY", "collect"]


class RealRobot:
    """The perturbed MuJoCo robot, recording joint states under PD at ``1 / rate_hz``.

    Args:
        robot: The nominal robot: fixed base (on a stand, :meth:`record`) or floating base (standing on a floor,
            :meth:`reset` / :meth:`step`).
        mismatch: How the real robot differs.
        rate_hz: Recording (and command) rate [Hz].
        contact: :class:`~wresdyn.robot.ground.ContactSettings` of the nominal floor (floating base only; default
            ``ContactSettings()``); the real floor is it with the mismatch's friction and softness
            (:func:`~wresdyn.data.mismatch.floor_contact`).
    """

    def __init__(self, robot: Robot, mismatch: Mismatch | None = None, rate_hz: float = 500.0, contact=None):
        import mujoco

        floating = robot.base == "floating"
        if floating:
            check_floating(robot)
        elif contact is not None:
            raise RobotError(f"{robot.source}: contact settings need a floating base: the fixed base hangs on a stand")
        self.robot, self.mismatch, self.rate_hz = robot, mismatch or Mismatch(), float(rate_hz)
        self.floating = floating
        self._v0 = 6 if floating else 0  # MuJoCo dof v0 + i is joint i (qpos 7 + i: after the free joint)
        dt = 1.0 / self.rate_hz
        sub = self.mismatch.substep or dt
        self.n_sub = int(round(dt / sub))
        if self.n_sub < 1 or abs(self.n_sub * sub - dt) > 1e-9 * dt:
            raise MismatchError(f"substep {sub} s does not divide the recording step {dt} s")
        self.substep = dt / self.n_sub
        self.n_delay = int(round(self.mismatch.delay / self.substep))
        self.contact = floor_contact(self.mismatch, contact) if floating else None
        """The real floor's :class:`~wresdyn.robot.ground.ContactSettings` (floating base), ``None`` on a stand."""
        self.model = build_mujoco(robot, self.substep, "implicitfast", ground=floating, contact=self.contact)
        perturb_mujoco(self.model, self.mismatch, robot, self._v0, np.random.default_rng(self.mismatch.seed))
        self._servo = self._servo_motors()
        self._mujoco = mujoco
        self._data = self._fifo = self._rng = None  # reset / step

    def _servo_motors(self) -> dict | None:
        """Turn the (perturbed) position actuators of servo joints (:attr:`Robot.servo`) into affine actuators
        (force = ctrl + bias_v qd, within the force range) whose ctrl and ``bias_v`` :meth:`_servo_ctrl` sets each
        physics step (and, on joints with stiction, the ``frictionloss``); returns the servo law's parameters, or None for a robot without servos (its actuators stay
        untouched)."""
        servo, m, n = self.robot.servo, self.model, self.robot.n_dof
        if servo is None:
            return None
        if self.floating:
            raise RobotError(f"{self.robot.source}: servo drives are supported on a fixed base only")
        s = servo.mask
        law = {"mask": s, "kp": m.actuator_gainprm[:n, 0].copy(), "kd": -m.actuator_biasprm[:n, 2].copy(),
               "effort": m.actuator_forcerange[:n, 1].copy(), "deadband": servo.deadband,
               "noload_speed": servo.noload_speed, "goal_accel": servo.goal_accel,
               "startup_torque": servo.startup_torque, "stiction": servo.stiction, "backlash": servo.backlash,
               "encoder_offset": servo.encoder_offset, "load_friction": servo.load_friction,
               "friction": m.dof_frictionloss[:n].copy()}
        idx = np.flatnonzero(s)
        m.actuator_gainprm[idx, 0] = 1.0
        m.actuator_biasprm[idx, :3] = 0.0
        m.actuator_ctrllimited[idx] = 0
        return law

    def _servo_ctrl(self, d, command, profile) -> np.ndarray:
        """MuJoCo ctrl for one physics step: the command on PD joints; on servo joints the servo law
        (:mod:`wresdyn.robot.servo`) split into its velocity term, the actuator's ``biasprm[2]`` (which
        ``implicitfast`` integrates implicitly, as SolverReplay does the law's), and the rest as ctrl."""
        law, m = self._servo, self.model
        n = len(command)
        goal = profile(command)
        e_m, contact = play(goal - (d.qpos[:n] + law["encoder_offset"]), law["backlash"])
        e_b = e_m - np.clip(e_m, -law["deadband"], law["deadband"])
        position = law["kp"] * e_b + law["startup_torque"] * np.clip(e_b / STARTUP_RAMP, -1.0, 1.0)
        raw = position - law["kd"] * d.qvel[:n]
        free = np.abs(raw) < law["effort"]
        emf = np.divide(law["effort"], law["noload_speed"], out=np.zeros(n), where=law["noload_speed"] > 0)
        # out of mesh the whole drive scales down (the force range then clamps what SolverReplay scales, within a tick)
        ctrl = contact * np.where(free, position, np.sign(raw) * law["effort"])
        s = law["mask"]
        m.actuator_biasprm[:n, 2] = np.where(s, -contact * (free * law["kd"] + emf), m.actuator_biasprm[:n, 2])
        if law["stiction"].any() or law["load_friction"].any():
            # the static friction on the velocity before the step and the load friction on the law's torque there,
            # as SolverReplay's
            drive = np.clip(ctrl + m.actuator_biasprm[:n, 2] * d.qvel[:n], -law["effort"], law["effort"])
            m.dof_frictionloss[:n] = np.where(s, friction_bound(d.qvel[:n], law["friction"], law["stiction"],
                                                                law["load_friction"], drive), m.dof_frictionloss[:n])
        return np.where(s, ctrl, command)

    def physics(self):
        """The true physical parameters of this robot in the simulator's terms
        (:class:`~wresdyn.robot.physical.PhysicalParams`), read back from the perturbed MuJoCo model: what an
        identification should find. Inertias are rotated from MuJoCo's principal frame into the body frame;
        the delay is the FIFO's length [s]."""
        from scipy.spatial.transform import Rotation

        m, n, r = self.model, self.robot.n_dof, self.robot
        dof = slice(self._v0, self._v0 + n)
        rot = Rotation.from_quat(m.body_iquat[1:], scalar_first=True).as_matrix()
        inertia = rot @ (m.body_inertia[1:, :, None] * np.eye(3)) @ rot.transpose(0, 2, 1)
        effort = np.where(np.isfinite(r.effort), m.actuator_forcerange[:n, 1], np.inf)
        kp, kd = m.actuator_gainprm[:n, 0].copy(), -m.actuator_biasprm[:n, 2].copy()
        friction = m.dof_frictionloss[dof].copy()
        servo = {}
        if self._servo is not None:  # the motors' gains are the servo law's
            law = self._servo
            kp, kd = np.where(law["mask"], law["kp"], kp), np.where(law["mask"], law["kd"], kd)
            servo = {f: np.array(law[f], dtype=np.float64) for f in SERVO_FIELDS}
            if law["stiction"].any() or law["load_friction"].any():  # the sliding friction, not a step's bound
                friction = np.where(law["mask"], law["friction"], friction)
        return PhysicalParams(list(r.joint_names), list(r.body_names), kp, kd, m.dof_armature[dof].copy(),
                              m.dof_damping[dof].copy(), friction, effort,
                              np.full(n, self.n_delay * self.substep), m.body_mass[1:].copy(), m.body_ipos[1:].copy(),
                              inertia, **servo)

    def record(self, q_cmd: np.ndarray, rng: np.random.Generator | None = None, settle: float = 0.5,
               on_sample=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Execute joint commands under PD and record what the robot's sensors report.

        The robot starts at rest at ``q_cmd[0]`` and holds it for ``settle`` seconds (it sags under gravity
        and friction, as a real robot does before a recording starts); then command k is held from t_k to
        t_k+1, with t_k = k / rate_hz.

        Args:
            q_cmd: Commanded joint positions [rad], shape (T, n_dof).
            rng: Generator for the sensor noise (required when a noise is on).
            settle: Time holding ``q_cmd[0]`` before sample 0 [s].
            on_sample: Optional ``callable(k, model)`` called before the physics steps of sample k (after settling),
                which may change the MuJoCo model's fields in place: a robot whose mismatch drifts during the
                recording (:meth:`physics` reads the fields as they are then). ``None``: the robot stays as built.

        Returns:
            ``(q, qd, tau)``: measured joint positions [rad] and velocities [rad/s] at t_k, shape (T, n_dof);
            ``tau[k]`` is the actuator torque averaged over [t_k, t_k+1) [N*m] (noise-free, diagnostics only).
        """
        if self.floating:
            raise ValueError(f"{self.robot.source.name}: record runs on a stand (fixed base); drive a floating-base "
                             "robot with reset and step")
        mujoco, m, mm = self._mujoco, self.model, self.mismatch
        q_cmd = np.asarray(q_cmd, dtype=np.float64)
        t_len, n = q_cmd.shape
        if n != self.robot.n_dof:
            raise ValueError(f"q_cmd has {n} joints, the robot {self.robot.n_dof}")
        d = mujoco.MjData(m)
        d.qpos[:] = q_cmd[0]
        d.qvel[:] = 0.0
        fifo = deque([q_cmd[0]] * self.n_delay)
        profile = None if self._servo is None else GoalProfile(self._servo["goal_accel"], self.substep, q_cmd[0])

        def step(cmd):
            fifo.append(cmd)
            d.ctrl[:] = fifo.popleft() if profile is None else self._servo_ctrl(d, fifo.popleft(), profile)
            mujoco.mj_step(m, d)

        for _ in range(int(round(settle / self.substep))):
            step(q_cmd[0])
        q, qd, tau = np.empty((t_len, n)), np.empty((t_len, n)), np.zeros((t_len, n))
        for k in range(t_len):
            q[k], qd[k] = d.qpos, d.qvel
            if on_sample is not None:
                on_sample(k, m)
            for _ in range(self.n_sub):
                step(q_cmd[k])
                tau[k] += d.actuator_force
        tau /= self.n_sub
        if not (np.isfinite(q).all() and np.isfinite(qd).all()):
            raise SimulationDiverged(f"{self.robot.source.name}: the real robot simulation diverged")
        return self.sense(q, qd, rng) + (_quantise(tau, mm.torque_resolution),)

    def reset(self, state, rng: np.random.Generator | None = None) -> None:
        """Place the floating-base robot at ``state`` (a :class:`~wresdyn.robot.ground.FloatingState`, e.g.
        :func:`~wresdyn.robot.ground.standing_state`) for :meth:`step`.

        The delay line is filled with ``state.q`` (the motors held the start pose before it); ``rng`` draws the
        sensor noise of every following :meth:`step` (required when a noise is on).
        """

        if not self.floating:
            raise ValueError(f"{self.robot.source.name}: reset and step drive a floating-base robot; a fixed base "
                             "records with record")
        mm, n = self.mismatch, self.robot.n_dof
        if (mm.position_noise > 0 or mm.velocity_noise > 0) and rng is None:
            raise ValueError("sensor noise is on: pass a numpy Generator")
        q, qd = np.asarray(state.q, dtype=np.float64), np.asarray(state.qd, dtype=np.float64)
        if q.shape != (n,) or qd.shape != (n,):
            raise ValueError(f"state has {q.shape} joint positions and {qd.shape} velocities, the robot {n} joints")
        d = self._mujoco.MjData(self.model)
        d.qpos[:7], d.qvel[:6] = free_to_mujoco(self.robot, state.base_pose, state.base_twist)
        d.qpos[7:], d.qvel[6:] = q, qd
        self._mujoco.mj_forward(self.model, d)
        self._data, self._rng = d, rng
        self._fifo = deque([q.copy()] * self.n_delay)

    @property
    def state(self):
        """The true (noise-free) :class:`~wresdyn.robot.ground.FloatingState` after the last :meth:`reset` or
        :meth:`step`."""

        d = self._data
        if d is None:
            raise RuntimeError("call reset(state) first")
        pose, twist = free_from_mujoco(self.robot, d.qpos[:7], d.qvel[:6])
        return FloatingState(pose, twist, d.qpos[7:].copy(), d.qvel[6:].copy())

    def step(self, q_cmd: np.ndarray):
        """Hold the joint command ``q_cmd`` [rad], shape (n_dof,), for one period ``1 / rate_hz`` and return what
        the robot reports at its end: a :class:`~wresdyn.robot.ground.FloatingState` whose joint positions and
        velocities carry the mismatch's sensor noise and quantisation (as :meth:`record`'s); the base pose and
        twist are exact. The command reaches the motors after the mismatch's delay, through its torque limits.

        Raises:
            SimulationDiverged: the simulation produced a non-finite state.
        """

        if self._data is None:
            raise RuntimeError("call reset(state) first")
        q_cmd = np.array(q_cmd, dtype=np.float64)  # a copy: the delay line keeps it
        if q_cmd.shape != (self.robot.n_dof,):
            raise ValueError(f"q_cmd has shape {q_cmd.shape}, the robot {self.robot.n_dof} joints")
        d, fifo = self._data, self._fifo
        for _ in range(self.n_sub):
            fifo.append(q_cmd)
            d.ctrl[:] = fifo.popleft()
            self._mujoco.mj_step(self.model, d)
        if not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
            raise SimulationDiverged(f"{self.robot.source.name}: the real robot simulation diverged")
        true = self.state
        q, qd = self.sense(true.q[None], true.qd[None], self._rng)
        return FloatingState(true.base_pose, true.base_twist, q[0], qd[0])

    def sense(self, q, qd, rng):
        """What the robot's encoders report for the true ``q``, ``qd`` (..., n_dof) [rad, rad/s]: the mismatch's
        sensor noise (drawn from ``rng``, a numpy Generator, required when noise is on) and quantisation."""
        mm = self.mismatch
        if (mm.position_noise > 0 or mm.velocity_noise > 0) and rng is None:
            raise ValueError("sensor noise is on: pass a numpy Generator")
        if mm.position_noise > 0:
            q = q + mm.position_noise * rng.standard_normal(q.shape)
        if mm.velocity_noise > 0:
            qd = qd + mm.velocity_noise * rng.standard_normal(qd.shape)
        return _quantise(q, mm.encoder_resolution), _quantise(qd, mm.velocity_resolution)


def _quantise(a: np.ndarray, resolution: float) -> np.ndarray:
    return np.round(a / resolution) * resolution if resolution > 0 else a


COMMAND_RESOLUTION = 2.0 ** -16
"""Commands are sent as fixed point with this resolution [rad] (1.5e-5 rad, far below any joint's tracking
error); a power of two, so every command is exact in float32 and compresses well."""


def _f32(a: np.ndarray) -> np.ndarray:
    """Round to float32 precision (kept as float64): what the dataset stores, so storage is exact."""
    return np.asarray(a, dtype=np.float32).astype(np.float64)


SPAWN_KEYS = {"train": 0, "heldout": 1, "ood": 2, "validation": 3}
"""First spawn key of each split's seeds in :func:`collect`. Fixed per split, not its position in
:data:`~wresdyn.data.dataset.SPLITS`: train, held-out and OOD keep their schema-1 keys, so a dataset recorded
with a validation split has the same train, held-out and OOD arrays as one recorded without."""
PROBE_SPAWN_KEY = 4
"""First spawn key of the saturation probe trajectories' seeds in :func:`collect`."""


def collect(robot: Robot, mismatch: Mismatch, counts: dict[str, int], duration: float = 4.0, rate_hz: float = 500.0,
            seed: int = 0, excitation=None, store_tau: bool = True, progress=None, probe: int = 0, probe_config=None):
    """Draw excitations, execute them on the real robot and return the recorded :class:`~wresdyn.data.dataset.Dataset`.

    Trajectory i of a split draws from ``SeedSequence(seed, spawn_key=(SPAWN_KEYS[split], i))``, so it does not
    depend on how many trajectories the other splits hold. Train, validation and held-out use the training
    family (foot mode: the ellipsoid excitation, eq. 2; joint mode: multisines); out-of-distribution alternates
    the other families (:meth:`~wresdyn.data.excitation.Plan.families`). The mode and IK frames come from the
    excitation config (:func:`~wresdyn.data.excitation.plan`); the dataset stores the robot's gains config.

    Args:
        robot: Nominal robot (fixed base; foot mode: with the IK frames).
        mismatch: How the real robot differs.
        counts: Number of trajectories per split, e.g. ``{"train": 16, "validation": 4, "heldout": 4, "ood": 4}``.
        duration: Length of every trajectory [s].
        rate_hz: Command and recording rate [Hz].
        seed: Master seed.
        excitation: :class:`~wresdyn.data.excitation.ExcitationConfig` (default ranges, ``mode = "auto"``, when
            ``None``).
        store_tau: Keep the measured (diagnostic) torque in the trajectories.
        progress: Optional ``callable(str)`` receiving the plan's lines (foot IK: the workspace), a line per rejected
            draw and one line per recorded trajectory; a :class:`wresdyn.progress.Log` also draws a bar over them.
        probe: Saturation probe trajectories (:mod:`wresdyn.data.probe`, foot mode only) added to the training
            split after its other trajectories, named ``train_probe_000`` ...; trajectory i draws from spawn key
            ``(PROBE_SPAWN_KEY, i)``, so the other trajectories are those recorded without probes.
        probe_config: :class:`~wresdyn.data.probe.SaturationProbe` (default steps when ``None``).
    """
    import time

    unknown = sorted(set(counts) - set(SPLITS))
    if unknown:
        raise ValueError(f"unknown split(s) {unknown} in counts; choose from {SPLITS}")
    plan = ex.plan(robot, excitation, progress)
    cfg = plan.cfg
    real = RealRobot(robot, mismatch, rate_hz)
    families = {split: plan.families(split) for split in SPLITS}
    if probe and plan.mode != "foot":
        raise RobotError(f"{robot.source}: the saturation probe steps the foot IK chains; it needs the foot excitation")
    total, done = sum(counts.values()) + probe, 0
    trajs, params = [], {}
    draws = [(split, i, SPAWN_KEYS[split], f"{split}_{i:03d}") for split in SPLITS for i in range(counts.get(split, 0))]
    at = sum(1 for d in draws if d[0] == "train")
    draws[at:at] = [("train", i, PROBE_SPAWN_KEY, f"train_probe_{i:03d}") for i in range(probe)]
    with bar(progress, total, "collect") as recorded:
        for split, i, key, name in draws:
            start = time.perf_counter()
            seeds = np.random.SeedSequence(seed, spawn_key=(key, i)).spawn(2)
            rng_exc, rng_noise = np.random.default_rng(seeds[0]), np.random.default_rng(seeds[1])
            if key == PROBE_SPAWN_KEY:
                family = PROBE_FAMILY
                exc = saturation_probe(robot, plan.ik.chains, plan.ws.home, duration, rate_hz, rng_exc, probe_config)
            else:
                family = families[split][i % len(families[split])]
                exc = plan.generate(family, duration, rate_hz, rng_exc, progress)
            q_cmd = _f32(_quantise(exc.q_cmd, COMMAND_RESOLUTION))
            q, qd, tau = real.record(q_cmd, rng_noise)
            q, qd = _f32(q), _f32(qd)
            t = np.arange(len(q_cmd)) / rate_hz
            tau = _f32(tau) if store_tau else None
            trajs.append(Trajectory(name, split, t, q, qd, derive_qdd(qd, rate_hz), q_cmd, tau))
            params[name] = exc.params
            done += 1
            if progress:
                progress(f"[{done:>{len(str(total))}}/{total}] {name:<14} {family:<9} "
                         f"draws={exc.params['draws']:<2} {plan.describe(exc)}  "
                         f"|q - q_cmd| {np.abs(q - q_cmd).mean():.3f} rad  {time.perf_counter() - start:.1f} s")
            recorded.update(1)
    meta = {"generator": "wresdyn collect", "duration_s": duration,
            "excitation": {k: v for k, v in dataclasses.asdict(cfg).items()},
            **plan.meta(),
            "real_robot": {"substep_s": real.substep, "delay_substeps": real.n_delay, "integrator": "implicitfast",
                           "settle_s": 0.5},
            "trajectory_params": params}
    if probe:
        # an option left off is not written: a default probe's meta, and so its dataset's bytes, do not depend on it
        probe_meta = {k: v for k, v in dataclasses.asdict(probe_config or SaturationProbe()).items()
                      if k != "across" or v}
        meta["saturation_probe"] = {"trajectories": probe, **probe_meta}
    return Dataset(list(robot.joint_names), float(rate_hz), trajs, _display_path(robot.source), robot.source_sha256,
                   mismatch.to_dict(), int(seed), meta, robot.gains_record())


def _display_path(p: Path) -> str:
    """The robot path relative to the repository root when it lies below it (portable), else absolute."""
    p, root = Path(p).resolve(), REPO
    try:
        return str(p.relative_to(root))
    except ValueError:
        return str(p)
