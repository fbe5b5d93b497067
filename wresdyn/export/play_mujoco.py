"""Replay joint commands on an exported MJCF robot in MuJoCo, the residual network (ONNX) adding its torque.

Copied beside ``robot.xml`` by ``wresdyn export RUN --format mjcf``; it needs mujoco, numpy and, for the residual,
onnxruntime (nothing of wresdyn)::

    python play_mujoco.py robot.xml commands.npy --residual residual.onnx --out q.npy [--servo servo.json]

``commands.npy``: joint commands q_cmd [rad], (T, n) in the actuators' order, one per period 1 / rate [Hz] (the
model's time step is that period). The robot starts at rest at ``q_cmd[0]`` (``--q0``: a ``.npy`` start pose).
Each step: ctrl = q_cmd[k] (MuJoCo's position actuators apply the identified PD, command delay and force range);
the residual observes [q, q̇, q̈, q_cmd] of the actuated joints (rad, rad/s, rad/s², rad; q̈ the change of q̇ over
the last step, raw SI units: the network normalises inside) and its output [N m] goes into ``qfrc_applied`` on
those joints, beside the actuators and not clamped with them; then ``mj_step``.
"""

from __future__ import annotations

import argparse
import json

import numpy as np


class Residual:
    """The exported residual network, ``obs (1, 4n) -> tau (1, n)`` [N m] (a GRU carries its hidden state)."""

    def __init__(self, path: str, dt: float) -> None:
        import onnxruntime

        self.session = onnxruntime.InferenceSession(str(path), providers=["CPUExecutionProvider"])
        self.inputs = [i.name for i in self.session.get_inputs()]
        h = next((i for i in self.session.get_inputs() if i.name == "h_in"), None)
        self.h_shape = None if h is None else (int(h.shape[0]), 1, int(h.shape[2]))
        self.dt = float(dt)
        self.reset()

    def reset(self, qdd0=None) -> None:
        """New rollout: hidden state zero; ``qdd0`` the start's q̈ [rad/s²] (default 0)."""
        self.h = None if self.h_shape is None else np.zeros(self.h_shape, dtype=np.float32)
        self.qd_prev, self.qdd0 = None, qdd0

    def torque(self, q, qd, q_cmd) -> np.ndarray:
        if self.qd_prev is None:
            qdd = np.zeros_like(qd) if self.qdd0 is None else np.asarray(self.qdd0, dtype=np.float64)
        else:
            qdd = (qd - self.qd_prev) / self.dt
        self.qd_prev = np.array(qd)
        obs = np.concatenate([q, qd, qdd, q_cmd])[None].astype(np.float32)
        feed = {"obs": obs} if self.h is None else {"obs": obs, "h_in": self.h}
        out = self.session.run(None, feed)
        if self.h is not None:
            self.h = out[1]
        return out[0][0].astype(np.float64)


class GoalProfile:
    """A servo's goal-acceleration profile on the command stream (the servo firmware's, which no MuJoCo actuator
    has): each joint's goal moves toward its command with at most ``goal_accel`` [rad/s²] (0: follows the command),
    at the speed that still stops on it, from rest at the first command."""

    def __init__(self, goal_accel, dt: float, start) -> None:
        self.on = np.asarray(goal_accel, dtype=np.float64) > 0
        self.accel = np.where(self.on, goal_accel, 1.0) * dt * dt  # [rad/step²]
        self.pos, self.vel = np.array(start, dtype=np.float64), np.zeros(len(self.on))

    def __call__(self, command) -> np.ndarray:
        e = command - self.pos
        want = np.sign(e) * np.minimum(np.sqrt(2.0 * self.accel * np.abs(e)), np.abs(e))
        vel = self.vel + np.clip(want - self.vel, -self.accel, self.accel)
        self.pos, self.vel = np.where(self.on, self.pos + vel, command), np.where(self.on, vel, 0.0)
        return self.pos.copy()


class ServoLaw:
    """The servo drives' whole law (``servo.json``'s ``law``: wresdyn's servo model, which MuJoCo's position
    actuators carry only in part), per joint, in SI units::

        e = goal_delayed - (q + encoder_offset); e_m = e - clip(e, -backlash, backlash)
        g = min(|e_m| / ramp, 1) where backlash > 0 else 1            the gear train's contact
        e_b = e_m - clip(e_m, -deadband, deadband)
        u = clip(kp e_b + startup_torque clip(e_b / ramp, -1, 1) - kd qd, -effort, effort)
        tau = g clip(u - (effort / noload_speed) qd, -effort, effort)  into qfrc_applied
        frictionloss = friction + stiction max(1 - |qd| / stiction_speed, 0) + load_friction |tau|

    With it the servo joints' actuators are silenced (their gains set to 0 in the replay's copy of the model) but keep
    recording the commands, so the delayed goal is the actuator's own (``mj_readCtrl``); the back-EMF leaves the
    joint damping, where the export put it for the plain MJCF, and the law carries it."""

    def __init__(self, law: dict, model) -> None:
        self.p = {k: np.asarray(v, dtype=np.float64) for k, v in law.items() if k not in ("ramp", "stiction_speed")}
        self.mask = self.p["mask"] > 0
        self.p.setdefault("load_friction", np.zeros(len(self.mask)))  # a servo.json written before the field
        self.ramp, self.v_s = float(law["ramp"]), float(law["stiction_speed"])
        self.emf = np.divide(self.p["effort"], self.p["noload_speed"], out=np.zeros(len(self.mask)),
                             where=self.p["noload_speed"] > 0)

    def silence(self, model, va) -> None:
        """Turn the servo joints' actuators off and their joint damping back to the identified one."""
        idx = np.flatnonzero(self.mask)
        model.actuator_gainprm[idx, 0] = 0.0
        model.actuator_biasprm[idx, :3] = 0.0
        model.dof_damping[va[idx]] = self.p["damping"][idx]

    def torque(self, goal, q, qd) -> np.ndarray:
        p = self.p
        e = goal - (q + p["encoder_offset"])
        e_m = e - np.clip(e, -p["backlash"], p["backlash"])
        g = np.where(p["backlash"] > 0, np.minimum(np.abs(e_m) / self.ramp, 1.0), 1.0)
        e_b = e_m - np.clip(e_m, -p["deadband"], p["deadband"])
        u = np.clip(p["kp"] * e_b + p["startup_torque"] * np.clip(e_b / self.ramp, -1.0, 1.0) - p["kd"] * qd,
                    -p["effort"], p["effort"])
        return np.where(self.mask, g * np.clip(u - self.emf * qd, -p["effort"], p["effort"]), 0.0)

    def friction(self, qd, tau=0.0) -> np.ndarray:
        """The frictionloss of the step at velocity ``qd`` and the law's drive torque ``tau`` [N m]."""
        return (self.p["friction"] + self.p["stiction"] * np.maximum(1.0 - np.abs(qd) / self.v_s, 0.0)
                + self.p["load_friction"] * np.abs(tau))


def joint_addresses(model) -> tuple[np.ndarray, np.ndarray]:
    """qpos and dof address of each actuator's joint (the actuators are the robot's joints, in order)."""
    joints = model.actuator_trnid[:, 0]
    return model.jnt_qposadr[joints], model.jnt_dofadr[joints]


def replay(model, q_cmd, q0=None, qd0=None, residual: Residual | None = None, qdd0=None,
           goal_accel=None, law: dict | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Open-loop replay of commands ``q_cmd`` (T, n) [rad] from joint state ``q0``, ``qd0`` (default: at rest at
    ``q_cmd[0]``); returns joint positions and velocities (T, n) at the start of each step (row 0 the start).

    The command delay's history starts filled with ``q_cmd[0]`` (the robot held its first command before).
    ``goal_accel`` (n,) [rad/s²]: servo joints' goal profile (``servo.json``), applied to the commands before the
    actuators (whose delay then follows it: the same as after it for whole steps of delay). ``law``: the servo
    drives' whole law (``servo.json``'s ``law``, :class:`ServoLaw`), replayed on a copy of ``model``."""
    import copy

    import mujoco

    q_cmd = np.asarray(q_cmd, dtype=np.float64)
    qa, va = joint_addresses(model)
    servo = None
    if law is not None:
        model = copy.deepcopy(model)
        servo = ServoLaw(law, model)
        servo.silence(model, va)
        sa = np.flatnonzero(servo.mask)
        delayed = np.zeros(1)
    d = mujoco.MjData(model)
    d.qpos[qa] = q_cmd[0] if q0 is None else q0
    d.qvel[va] = 0.0 if qd0 is None else qd0
    for i in range(model.nu):
        n_sample = int(model.actuator_history[i, 0])
        if n_sample > 0:
            mujoco.mj_initCtrlHistory(model, d, i, None, np.full((n_sample, 1), q_cmd[0, i]))
    if residual is not None:
        residual.reset(qdd0)
    profile = None if goal_accel is None else GoalProfile(goal_accel, model.opt.timestep, q_cmd[0])
    t_len = len(q_cmd)
    q, qd = np.empty((t_len, model.nu)), np.empty((t_len, model.nu))
    for k in range(t_len):
        q[k], qd[k] = d.qpos[qa], d.qvel[va]
        d.ctrl[:] = q_cmd[k] if profile is None else profile(q_cmd[k])
        tau = np.zeros(model.nu) if residual is None else residual.torque(q[k], qd[k], q_cmd[k])
        if servo is not None:
            goal = np.array(d.ctrl)
            for i in sa:  # the goal the actuator's delay line holds, as the position actuator would read it
                if model.actuator_history[i, 0] > 0:
                    r = mujoco.mj_readCtrl(model, d, int(i), d.time - model.actuator_delay[i], delayed,
                                           int(model.actuator_history[i, 1]))
                    goal[i] = (delayed if r is None else r)[0]
            drive = servo.torque(goal, q[k], qd[k])
            tau = tau + drive
            model.dof_frictionloss[va[sa]] = servo.friction(qd[k], drive)[sa]
        if residual is not None or servo is not None:
            d.qfrc_applied[va] = tau
        mujoco.mj_step(model, d)
    return q, qd


def main(argv=None) -> int:
    import mujoco

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("xml", help="the exported robot.xml")
    p.add_argument("commands", help=".npy of joint commands [rad], (T, n)")
    p.add_argument("--residual", help="residual.onnx (omit for the identified physics alone)")
    p.add_argument("--servo", help="servo.json of the export (servo joints' goal profile)")
    p.add_argument("--position-actuators", action="store_true",
                   help="servo joints on the MJCF's position actuators alone, without servo.json's law")
    p.add_argument("--q0", help=".npy start joint positions [rad], (n,)")
    p.add_argument("--out", help=".npy to write the joint positions [rad], (T, n)")
    a = p.parse_args(argv)
    model = mujoco.MjModel.from_xml_path(a.xml)
    residual = Residual(a.residual, model.opt.timestep) if a.residual else None
    servo = {} if a.servo is None else json.loads(open(a.servo).read())
    q, _ = replay(model, np.load(a.commands), None if a.q0 is None else np.load(a.q0), residual=residual,
                  goal_accel=servo.get("goal_accel"), law=None if a.position_actuators else servo.get("law"))
    if a.out:
        np.save(a.out, q)
    print(f"{len(q)} steps of {model.opt.timestep:g} s; final q {np.round(q[-1], 4).tolist()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
