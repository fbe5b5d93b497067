"""A robot on the floor in many CPU worlds: Newton's ``SolverMuJoCo`` model, stepped in C threads.

Newton's ``SolverMuJoCo`` runs MuJoCo C for one world only; for several it takes mujoco_warp, which on Warp's CPU
device runs each kernel's threads one after another (the humanoid on the floor: 2.7k env-steps/s at 64 worlds on
2 cores, against ~10k per core for MuJoCo C). :class:`SolverMuJoCoThreads` keeps Newton's conversion of the robot
(``SolverMuJoCo(use_mujoco_cpu=True)`` on a one-world copy of the model: its ``mj_model``, contacts and drives
included, updated by Newton's own ``notify_model_changed``) and steps every world of the batch with
``mujoco.rollout`` in C threads. Every world carries the physics of world 0 (a skill's worlds share one robot).

State travels through Newton's arrays (``joint_q``, ``joint_qd`` in, the same and ``body_q``/``body_qd`` out by
``newton.eval_fk``), so :class:`~wresdyn.sim.simulator.Simulator` drives it like any Newton solver; each step
starts MuJoCo's constraint solver cold (no warm start carried between steps), as
:class:`~wresdyn.skills.plants.RealPlant` does.
"""

from __future__ import annotations

import os

import numpy as np

from ..robot.contact import ContactSettings
from ..robot.ground import base_index
from ..robot.mujoco_model import free_from_mujoco, free_to_mujoco
from .physics import MODEL_ARRAYS

__all__ = ["SolverMuJoCoThreads"]


def _threads(num_worlds: int, threads: int | None) -> int:
    if threads is None:
        threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    return max(1, min(int(threads), num_worlds))


class SolverMuJoCoThreads:
    """Newton solver interface (``step``, ``notify_model_changed``) over ``model.world_count`` MuJoCo C worlds.

    Args:
        model: The Newton model of every world (CPU, ``Robot.build_model(n, ground=True)``).
        robot: Its :class:`~wresdyn.robot.Robot` (a floating base).
        contact: :class:`~wresdyn.robot.ground.ContactSettings` (default ``ContactSettings()``).
        threads: C threads (default: every core this process may use).
    """

    def __init__(self, model, robot, contact=None, threads: int | None = None) -> None:
        import mujoco
        import newton
        from mujoco import rollout

        c = contact or ContactSettings()
        self.model, self.robot = model, robot
        self.num_worlds = int(model.world_count)
        self._template = robot.build_model(1, "cpu", ground=True, contact=contact)
        self._inner = newton.solvers.SolverMuJoCo(
            self._template, use_mujoco_cpu=True, disable_contacts=False, integrator="implicitfast", solver=c.solver,
            cone=c.cone, iterations=c.iterations, ls_iterations=c.ls_iterations, impratio=c.impratio,
            enable_multiccd=False)
        self.mj_model = self._inner.mj_model
        m, n = self.mj_model, robot.n_dof
        if m.nq != 7 + n or m.nv != 6 + n or m.nu != n:
            raise ValueError(f"{robot.source.name}: SolverMuJoCoThreads needs a free base and one drive per joint "
                             f"(MuJoCo nq {m.nq}, nv {m.nv}, nu {m.nu} for {n} joints)")
        drive_dof = m.jnt_dofadr[m.actuator_trnid[:, 0]]
        if not np.array_equal(drive_dof, 6 + np.arange(n)):
            raise ValueError(f"{robot.source.name}: MuJoCo drives are not in joint order ({drive_dof})")
        self._mj, self._rollout, self._newton = mujoco, rollout, newton
        self._spec = int(mujoco.mjtState.mjSTATE_FULLPHYSICS)
        self._ctrl_spec = int(mujoco.mjtState.mjSTATE_CTRL) | int(mujoco.mjtState.mjSTATE_QFRC_APPLIED)
        self._datas = [mujoco.MjData(m) for _ in range(_threads(self.num_worlds, threads))]
        d = self._datas[0]
        d.qpos[:], d.qvel[:] = np.arange(1, m.nq + 1), -np.arange(1, m.nv + 1)
        s = np.empty(mujoco.mj_stateSize(m, self._spec))
        mujoco.mj_getState(m, d, s, self._spec)
        self._iq, self._iv = int(np.flatnonzero(s == 1.0)[0]), int(np.flatnonzero(s == -1.0)[0])
        mujoco.mj_resetData(m, d)
        mujoco.mj_getState(m, d, s, self._spec)
        self._state = np.tile(s, (self.num_worlds, 1))
        """Full physics state of every world (nbatch, nstate): MuJoCo's qpos/qvel with activations and time."""
        q0, qd0 = base_index(robot)
        self._nq, self._nqd = model.joint_coord_count // self.num_worlds, model.joint_dof_count // self.num_worlds
        self._base_q, self._base_qd = slice(q0, q0 + 7), slice(qd0, qd0 + 6)
        self._q_index, self._qd_index = np.asarray(robot.q_index), np.asarray(robot.qd_index)

    def notify_model_changed(self, flags) -> None:
        """Copy world 0's parameters into the one-world template and let Newton rewrite its MuJoCo model."""

        for name in MODEL_ARRAYS.values():
            dst = getattr(self._template, name)
            dst.assign(getattr(self.model, name).numpy()[:len(dst)])
        self._inner.notify_model_changed(flags)

    def step(self, state_in, state_out, control, contacts, dt: float) -> None:
        """One step of ``dt`` [s] for every world: PD targets ``control.joint_target_q`` and joint forces
        ``control.joint_f`` (actuated DoFs) held over it."""

        w, n, m = self.num_worlds, self.robot.n_dof, self.mj_model
        jq = state_in.joint_q.numpy().reshape(w, self._nq).astype(np.float64)
        jqd = state_in.joint_qd.numpy().reshape(w, self._nqd).astype(np.float64)
        qpos_b, qvel_b = free_to_mujoco(self.robot, jq[:, self._base_q], jqd[:, self._base_qd])
        s = self._state
        s[:, self._iq:self._iq + 7], s[:, self._iv:self._iv + 6] = qpos_b, qvel_b
        s[:, self._iq + 7:self._iq + 7 + n], s[:, self._iv + 6:self._iv + 6 + n] = jq[:, self._q_index], \
            jqd[:, self._qd_index]
        target = control.joint_target_q.numpy().reshape(w, self._nq)[:, self._q_index]
        force = np.zeros((w, m.nv))
        force[:, 6:] = control.joint_f.numpy().reshape(w, self._nqd)[:, self._qd_index]
        m.opt.timestep = dt
        ctrl = np.concatenate([target, force], axis=-1)[:, None, :]
        states, _ = self._rollout.rollout(m, self._datas, s, ctrl, control_spec=self._ctrl_spec, nstep=1,
                                          persistent_pool=True)
        self._state = states[:, 0].copy()
        s = self._state
        pose, twist = free_from_mujoco(self.robot, s[:, self._iq:self._iq + 7], s[:, self._iv:self._iv + 6])
        jq[:, self._base_q], jqd[:, self._base_qd] = pose, twist
        jq[:, self._q_index] = s[:, self._iq + 7:self._iq + 7 + n]
        jqd[:, self._qd_index] = s[:, self._iv + 6:self._iv + 6 + n]
        state_out.joint_q.assign(jq.reshape(-1).astype(np.float32))
        state_out.joint_qd.assign(jqd.reshape(-1).astype(np.float32))
        self._newton.eval_fk(self.model, state_out.joint_q, state_out.joint_qd, state_out)
