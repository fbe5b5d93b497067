"""The exported residual in a plain Newton loop: the one small component a Newton script imports from wresdyn.

Newton's actuators compute each joint's effort from that joint's own state and command; the residual is one
network over every joint's [q, q̇, q̈, q_cmd], so it runs beside them and adds its torque to ``control.joint_f``
after they have written theirs, the mechanism Newton documents for external joint efforts (the residual is
not clamped with the drive, as in wresdyn's own simulator). It imports numpy, torch, warp and pxr only (and :mod:`wresdyn.learn.network_file`, the file format)::

    import newton
    from wresdyn.export.residual_torque import ResidualTorque

    builder = newton.ModelBuilder()
    builder.add_usd("export/actuated.usda")           # identified physics + PD, delay, clamping actuators
    model = builder.finalize()
    residual = ResidualTorque.from_usd("export/actuated.usda", model)
    ...
    control.joint_target_q.assign(q_cmd)               # the command, every world
    control.joint_f.zero_()
    for a, s0, s1 in zip(model.actuators, act_states, act_next):
        a.step(state, control, s0, s1, dt=dt)
    residual.apply(state, control, q_cmd)              # + tau_res [N m]
    solver.step(state, state_next, control, None, dt)

:meth:`ResidualTorque.apply` observes the state it is given and the command, as wresdyn's rollout does:
q̈ is the change of q̇ between its calls divided by the period (call :meth:`ResidualTorque.reset` at a new start).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..learn.network_file import load_residual

__all__ = ["ResidualTorque"]


class ResidualTorque:
    """An exported residual ``obs (N, 4n) -> tau (N, n)`` [N m] on ``n`` joints of every world of a Newton model.

    Args:
        network: The residual (``forward``, ``reset``): wresdyn's ``residual.pt2`` loaded by
            :func:`wresdyn.learn.network_file.load_residual`.
        model: The Newton model (one robot per world, ``model.world_count`` worlds).
        joint_paths: USD prim path of each of the network's joints, in its order.
        dt: Period between :meth:`apply` calls [s] (the q̈ estimate's step).
    """

    def __init__(self, network, model, joint_paths: list[str], dt: float) -> None:
        import torch
        import warp as wp

        self.network, self.dt = network, float(dt)
        labels = list(model.joint_label)
        worlds = max(int(getattr(model, "world_count", 1)), 1)
        qd_start, q_start = model.joint_qd_start.numpy(), model.joint_q_start.numpy()
        per_path: dict[str, list[int]] = {}
        for j, label in enumerate(labels):
            per_path.setdefault(label, []).append(j)
        qi, qdi = [], []
        for p in joint_paths:
            js = per_path.get(p, [])
            if len(js) != worlds:
                raise ValueError(f"residual joint {p!r}: found in {len(js)} of the model's {worlds} worlds")
            qi.append([int(q_start[j]) for j in js])
            qdi.append([int(qd_start[j]) for j in js])
        self.device = torch.device(str(wp.device_to_torch(model.device)))
        self.q_index = torch.as_tensor(np.array(qi).T, device=self.device)  # (worlds, n)
        self.qd_index = torch.as_tensor(np.array(qdi).T, device=self.device)
        self.network.to(self.device)
        self._qd_prev = None  # q̇ of the previous call, (worlds, n), updated in place
        self._qdd0 = None  # q̈ at a start (reset), (worlds, n) [rad/s²]

    @classmethod
    def from_usd(cls, usd_path: str | Path, model, dt: float | None = None) -> "ResidualTorque":
        """Read the ``wresdyn_residual`` prim of an exported ``actuated.usda`` and load its network (the
        ``torch.export`` archive its ``wresdyn:program`` names)."""
        from pxr import Usd

        stage = Usd.Stage.Open(str(usd_path))
        prim = next((p for p in stage.Traverse() if p.GetName() == "wresdyn_residual"), None)
        if prim is None:
            raise ValueError(f"{usd_path}: no wresdyn_residual prim (export a run with a residual)")
        asset = prim.GetAttribute("wresdyn:program").Get()
        path = asset.resolvedPath or str(Path(usd_path).parent / asset.path)
        joints = [str(t) for t in prim.GetRelationship("wresdyn:joints").GetTargets()]
        rate = float(prim.GetAttribute("wresdyn:rateHz").Get())
        return cls(load_residual(path), model, joints, dt or 1.0 / rate)

    def reset(self, qdd=None) -> None:
        """Start a new rollout: the network's memory cleared; ``qdd`` (worlds, n) [rad/s²] the start's q̈ (default 0)."""
        self.network.reset()
        self._qdd0 = qdd
        self._qd_prev = None

    def torque(self, state, q_cmd):
        """The residual torque (worlds, n) [N m] at ``state`` under command ``q_cmd`` (worlds, n) [rad] (torch).

        CUDA-graph safe for an MLP residual once called outside the capture (the q̇ memory is updated in place):
        pass ``q_cmd`` as a device tensor (e.g. a gather from ``control.joint_target_q``), not host data. A GRU
        keeps its hidden state by rebinding it, so capture only MLP residuals."""
        import torch
        import warp as wp

        q_all, qd_all = wp.to_torch(state.joint_q), wp.to_torch(state.joint_qd)
        q, qd = q_all[self.q_index], qd_all[self.qd_index]
        if self._qd_prev is None:
            qdd = torch.zeros_like(qd) if self._qdd0 is None else \
                torch.as_tensor(self._qdd0, dtype=qd.dtype, device=self.device).reshape(qd.shape)
            self._qd_prev = qd.clone()
        else:
            qdd = (qd - self._qd_prev) / self.dt
            self._qd_prev.copy_(qd)
        cmd = torch.as_tensor(q_cmd, dtype=q.dtype, device=self.device).reshape(q.shape)
        with torch.no_grad():
            return self.network(torch.cat([q, qd, qdd, cmd], dim=-1))

    def apply(self, state, control, q_cmd) -> None:
        """Add the residual torque at ``state`` under ``q_cmd`` to ``control.joint_f`` (call after the actuators)."""
        import warp as wp

        tau = self.torque(state, q_cmd)
        f = wp.to_torch(control.joint_f)
        f.index_put_((self.qd_index.reshape(-1),), tau.reshape(-1).to(f.dtype), accumulate=True)
