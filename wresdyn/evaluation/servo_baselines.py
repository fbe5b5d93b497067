"""Published servo models of the SO-101 (Feetech STS3215) replayed in MuJoCo C on recorded runs, scored with the
same metric as the project's models (:func:`wresdyn.evaluation.open_loop.metrics`: mean |Δq| over the fitted joints
of whole runs, open loop from the first recorded state, driven by the recorded commands).

* **LeRobot's SO-101 MuJoCo model as it is**: huggingface/lerobot, ``src/lerobot/robots/so101_follower/sim/``
  (``so101_new_calib.xml`` and ``joints_properties.xml``, commit 56df5f2): the SO-ARM100 "new_calib" arm of
  ``scenes/so101/so101.xml`` whose ``sts3215`` default class has joint damping 0.60 N·m·s/rad, frictionloss
  0.052 N·m, armature 0.028 kg·m² and a position actuator ``kp="17.8"`` (no kv), each actuator force-limited to
  ±3.35 N·m; its ±0.5° ``backlash`` class is defined but used by no joint. :func:`lerobot_model` is the project's
  file with those actuator gains (every other field is the same).
* **A BAM-style drive** (Rhoban's "Better Actuator Models", Rhoban/bam): the servo firmware's P law on the
  position error, duty = clip(kp · error_gain · (q_target − q), ±max_pwm) with the target moving at most
  max_velocity toward the command (``bam/feetech/actuator.py``, ``STS3215Actuator``), into a DC motor with back-EMF,
  τ = kt/R · vin · duty − kt²/R · q̇ (``VoltageControlledActuator.compute_torque``), against Coulomb friction
  (``frictionloss``) and viscous friction (``damping``) of the friction model (``bam/model.py``), applied in MuJoCo
  as ``bam/mujoco.py``'s ``MujocoController`` does: a motor torque computed each physics step from the state and the
  command, the friction terms written into the joint's ``frictionloss`` and ``damping``. BAM ships, for the STS3215 at
  7.4 V, the identified model m1 only (``params/feetech_sts3215_7_4V/m1.json``: Coulomb and viscous friction; its
  load-dependent and Stribeck terms are those of m3-m6, not identified for this servo, hence zero here).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from ..sim.rollout import Replays
from .open_loop import metrics

__all__ = ["LEROBOT_KP", "BamParams", "BAM_STS3215_7V4", "lerobot_model", "bam_model", "motors", "BamDrive", "PDDrive",
           "replay", "evaluate_baseline"]

LEROBOT_KP = 17.8
"""Position gain of LeRobot's ``sts3215`` class [N·m/rad] (its kv is MuJoCo's default, 0)."""


@dataclass(frozen=True)
class BamParams:
    """A BAM voltage-controlled servo with the m1 friction model (Rhoban/bam's names)."""

    kt: float
    """Torque constant [N·m/A] = back-EMF constant [V·s/rad]."""
    R: float
    """Motor resistance [Ohm]."""
    armature: float
    """Apparent rotor inertia at the joint [kg·m²]."""
    friction_base: float
    """Coulomb friction [N·m] (MuJoCo ``frictionloss``)."""
    friction_viscous: float
    """Viscous friction [N·m·s/rad] (MuJoCo ``damping``)."""
    vin: float = 7.4
    """Supply voltage [V]."""
    kp: float = 16.0
    """The firmware's P coefficient: LeRobot writes P_Coefficient 16 on every STS3215 of the SO-101 follower
    (BAM identified at 32)."""
    error_gain: float = 0.166
    """Duty cycle per (kp · rad) of position error (BAM's oscilloscope measurement on STS3215)."""
    max_pwm: float = 0.97
    """Largest duty cycle."""
    max_velocity: float = 3400 * 2 * math.pi / 4096
    """Fastest move of the firmware's internal target [rad/s] (BAM's default for the STS3215)."""


BAM_STS3215_7V4 = BamParams(kt=1.21164135295077, R=2.6761663274455603, armature=0.02840336348682085,
                            friction_base=0.05239296084748866, friction_viscous=0.05908515565091076)
"""Rhoban/bam ``params/feetech_sts3215_7_4V/m1.json`` (commit 2d26b69); its ``q_offset`` (−0.051 rad) is the
offset of BAM's test bench, not of the servo, and is left out."""


def _load(robot_file, rate_hz: float):
    import mujoco

    m = mujoco.MjModel.from_xml_path(str(robot_file))
    m.opt.timestep = 1.0 / rate_hz
    if m.nu != m.njnt or m.nq != m.nv:
        raise ValueError(f"{robot_file}: expected one hinge actuator per joint and no free joint")
    return m


def lerobot_model(robot_file, rate_hz: float):
    """LeRobot's SO-101 model: ``robot_file`` (``scenes/so101/so101.xml``) with the position actuators' gains of
    LeRobot's ``sts3215`` class (kp 17.8 N·m/rad, kv 0); MuJoCo steps at ``1 / rate_hz``."""
    m = _load(robot_file, rate_hz)
    m.actuator_gainprm[:, 0] = LEROBOT_KP
    m.actuator_biasprm[:, 1] = -LEROBOT_KP
    m.actuator_biasprm[:, 2] = 0.0
    return m


def bam_model(robot_file, rate_hz: float, params: BamParams = BAM_STS3215_7V4):
    """``robot_file`` with BAM's armature and friction on every joint and its actuators turned into unlimited
    motors (ctrl = torque [N·m]), for :class:`BamDrive`."""
    m = _load(robot_file, rate_hz)
    m.dof_armature[:] = params.armature
    m.dof_frictionloss[:] = params.friction_base
    m.dof_damping[:] = params.friction_viscous
    motors(m)
    return m


def motors(m) -> None:
    """Turn every actuator of ``m`` into a motor whose ctrl is its torque [N·m], unbounded (a drive computes it)."""
    m.actuator_gainprm[:, :] = 0.0
    m.actuator_gainprm[:, 0] = 1.0
    m.actuator_biasprm[:, :] = 0.0
    m.actuator_ctrllimited[:] = 0
    m.actuator_forcelimited[:] = 0


class BamDrive:
    """The BAM servo law, one physics step at a time; its state is the firmware's moving target."""

    def __init__(self, params: BamParams, q0: np.ndarray):
        self.p = params
        self.target = np.array(q0, dtype=np.float64)
        """The firmware's internal target [rad], shape (n,): starts at the recorded first position."""

    def __call__(self, q: np.ndarray, qd: np.ndarray, q_cmd: np.ndarray, dt: float) -> np.ndarray:
        p = self.p
        step = p.max_velocity * dt
        self.target = np.clip(q_cmd, self.target - step, self.target + step)
        duty = np.clip((self.target - q) * p.kp * p.error_gain, -p.max_pwm, p.max_pwm)
        return p.kt * (p.vin * duty) / p.R - p.kt**2 * qd / p.R


class PDDrive:
    """MuJoCo's position actuator as a torque law, τ = clip(kp·q_cmd − kp·q − kv·q̇, ±limit), in the order MuJoCo
    evaluates gain·ctrl + bias."""

    def __init__(self, kp: np.ndarray, kv: np.ndarray, limit: np.ndarray):
        self.kp, self.kv, self.limit = kp, kv, limit

    def __call__(self, q, qd, q_cmd, dt):
        return np.clip(self.kp * q_cmd + (-self.kp) * q + (-self.kv) * qd, -self.limit, self.limit)


def replay(m, trajectories, drive=None) -> Replays:
    """Replay each trajectory in MuJoCo from its first recorded state (q, q̇), command k held for step k.

    Args:
        m: The MuJoCo model (one actuator per joint, in the trajectories' joint order).
        trajectories: Recorded trajectories on the model's step (``q``, ``qd``, ``q_cmd``, each (T, n)).
        drive: ``None``: the model's own actuators with ctrl = the command; else a factory
            ``drive(q0) -> law`` with ``law(q, q̇, q_cmd, dt) -> torque`` (n,) written to the (motor) actuators
            before each step.

    Returns:
        :class:`~wresdyn.sim.rollout.Replays`; a replay that turns non-finite holds its last sane state.
    """
    import mujoco

    d = mujoco.MjData(m)
    dt = m.opt.timestep
    qs, qds, diverged = [], [], []
    for tr in trajectories:
        mujoco.mj_resetData(m, d)
        d.qpos[:], d.qvel[:] = tr.q[0], tr.qd[0]
        law = None if drive is None else drive(tr.q[0])
        t_len = len(tr.q)
        q, qd = np.empty((t_len, m.nq)), np.empty((t_len, m.nv))
        q[0], qd[0] = tr.q[0], tr.qd[0]
        at = -1
        for k in range(t_len - 1):
            d.ctrl[:] = tr.q_cmd[k] if law is None else law(d.qpos, d.qvel, tr.q_cmd[k], dt)
            mujoco.mj_step(m, d)
            if not (np.isfinite(d.qpos).all() and np.isfinite(d.qvel).all()):
                at = k + 1
                q[at:], qd[at:] = q[k], 0.0
                break
            q[k + 1], qd[k + 1] = d.qpos, d.qvel
        qs.append(q)
        qds.append(qd)
        diverged.append(at)
    return Replays(qs, qds, diverged)


def evaluate_baseline(m, trajectories, pd_only: dict, drive=None, weights=None) -> dict:
    """One model on one split: its :func:`~wresdyn.evaluation.open_loop.metrics` and the improvement over the
    PD-only metrics ``pd_only`` (a :func:`~wresdyn.evaluation.open_loop.evaluate_split` summary's ``"pd_only"``),
    mean |Δq| PD-only / model, as ``evaluate_split`` computes it for the project's models."""
    trajectories = list(trajectories)
    res = metrics(trajectories, replay(m, trajectories, drive), weights)
    return {"n_trajectories": len(trajectories), "pd_only": pd_only, "model": asdict(res),
            "improvement": pd_only["mean_abs_dq"] / res.mean_abs_dq if res.mean_abs_dq > 0 else None}

