"""The calibrated robot in a plain Newton script: load ``wresdyn export``'s USD, replay a recorded command.

Only Newton (with MuJoCo, for ``SolverMuJoCo``) and the small residual component are imported: the exported
``actuated.usda`` carries the identified physics (armature, damping, friction, masses, inertias) and the drive
path as ``newton.actuators`` (PD, delay, effort clamping), which Newton's importer builds into
``model.actuators``; :class:`~wresdyn.export.residual_torque.ResidualTorque` adds the residual network's torque.
Servo joints' actuators use the drive the export ships in ``servo_actuator.py`` (:func:`register_servo`).

    python examples/calibrated_robot_newton.py runs/fit/export data/dataset.npz --split heldout

prints the mean |Δq| of this replay against the recording (and, with ``--compare``, against wresdyn's own
corrected replay). ``SolverMuJoCo`` is the solver here: Newton's ``SolverFeatherstone`` does not apply joint
friction (``joint_friction``), which the identified model relies on.
"""

from __future__ import annotations

import argparse
import importlib.util
import sys
from pathlib import Path

import numpy as np


def load_calibrated(usd_path: str, device: str = "cpu"):
    """The exported robot (fixed base, as recorded on the stand): Newton model, its solver and the residual."""
    import newton

    from wresdyn.export.residual_torque import ResidualTorque

    register_servo(Path(usd_path).parent)
    builder = newton.ModelBuilder()
    builder.add_usd(usd_path, floating=False, enable_self_collisions=False, load_visual_shapes=False)
    model = builder.finalize(device=device)
    solver = newton.solvers.SolverMuJoCo(model, use_mujoco_cpu=device == "cpu", disable_contacts=True,
                                         integrator="implicitfast")
    residual = ResidualTorque.from_usd(usd_path, model) if _has_residual(usd_path) else None
    return model, solver, residual


def register_servo(export: Path) -> None:
    """Load the export's ``servo_actuator.py`` (a robot with servo drives) and register its drive and USD schema
    with Newton, once per process and before any USD stage is opened (USD builds its schema registry once)."""
    path = export / "servo_actuator.py"
    if not path.is_file() or "servo_actuator" in sys.modules:
        return
    spec = importlib.util.spec_from_file_location("servo_actuator", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules["servo_actuator"] = module
    spec.loader.exec_module(module)
    module.register()


def _has_residual(usd_path: str) -> bool:
    from pxr import Usd

    stage = Usd.Stage.Open(usd_path)  # held while traversing
    return any(p.GetName() == "wresdyn_residual" for p in stage.Traverse())


def replay(usd_path: str, q0, qd0, qdd0, q_cmd, dt: float) -> np.ndarray:
    """Open-loop replay of ``q_cmd`` (T, n) [rad] from (q0, qd0) (n,) [rad, rad/s]; q̈ at the start ``qdd0``
    [rad/s²] (the residual's first observation). Returns q (T, n) [rad]: the start, then after each step
    (step k holds command k for ``dt`` seconds). Joint order: the residual's (the recording's)."""
    import newton
    import warp as wp

    model, solver, residual = load_calibrated(usd_path)
    s0, s1, control = model.state(), model.state(), model.control()
    if residual is None:
        raise ValueError(f"{usd_path}: no residual to replay with")
    qi, qdi = residual.q_index[0].cpu().numpy(), residual.qd_index[0].cpu().numpy()
    q, qd = s0.joint_q.numpy(), s0.joint_qd.numpy()
    q[qi], qd[qdi] = q0, qd0
    s0.joint_q.assign(q)
    s0.joint_qd.assign(qd)
    newton.eval_fk(model, s0.joint_q, s0.joint_qd, s0)
    act, act_next = [a.state() for a in model.actuators], [a.state() for a in model.actuators]
    residual.reset(np.asarray(qdd0)[None])
    target = control.joint_target_q.numpy()
    out = [np.asarray(q0, dtype=np.float64)]
    for k in range(len(q_cmd) - 1):
        target[qi] = q_cmd[k]
        control.joint_target_q.assign(target)
        control.joint_f.zero_()
        for a, sa, sb in zip(model.actuators, act, act_next):
            a.step(s0, control, sa, sb, dt=dt)
        residual.apply(s0, control, q_cmd[k][None])
        solver.step(s0, s1, control, None, dt)
        s0, s1 = s1, s0
        act, act_next = act_next, act
        out.append(wp.to_torch(s0.joint_q)[residual.q_index[0]].cpu().double().numpy())
    return np.stack(out)


def main() -> None:
    import torch
    import warp as wp

    wp.config.quiet = True
    torch.set_num_threads(1)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("export", help="folder written by `wresdyn export`")
    p.add_argument("data", help="dataset (.npz) recorded on the robot")
    p.add_argument("--split", default="heldout")
    p.add_argument("--seconds", type=float, default=2.0, help="replay length per trajectory [s]")
    p.add_argument("--compare", action="store_true", help="also replay with wresdyn and print the difference")
    p.add_argument("--save", default=None, help="write the replayed q [rad] per trajectory name to this .npz")
    args = p.parse_args()
    from wresdyn.data.dataset import load_dataset

    ds = load_dataset(args.data)
    dt = 1.0 / ds.rate_hz
    steps = int(round(args.seconds * ds.rate_hz)) + 1
    errs, diffs, saved = [], [], {}
    for t in ds.split(args.split):
        n = min(steps, len(t.q))
        q = saved[t.name] = replay(f"{args.export}/actuated.usda", t.q[0], t.qd[0], t.qdd[0], t.q_cmd[:n], dt)
        errs.append(np.abs(q - t.q[:n]).mean())
        line = f"{t.name}: plain Newton vs recording {errs[-1]:.4f} rad"
        if args.compare:
            qw = _wresdyn_replay(args.export, args.data, t, n)
            diffs.append(np.abs(q - qw).mean())
            line += f", vs wresdyn's corrected replay {diffs[-1]:.4f} rad (max {np.abs(q - qw).max():.4f})"
        print(line, flush=True)
    if args.save:
        np.savez(args.save, **saved)
    print(f"{args.split}: {len(errs)} trajectories, mean |dq| {np.mean(errs):.4f} rad"
          + (f", vs wresdyn {np.mean(diffs):.4f} rad" if diffs else ""))


def _wresdyn_replay(export: str, data: str, traj, n: int) -> np.ndarray:
    from wresdyn.data.loading import load_data
    from wresdyn.learn.network_file import load_residual
    from wresdyn.sim.physics import PhysicalParams
    from wresdyn.sim.rollout import replay_trajectories

    ds, robot = load_data(data)
    physics = PhysicalParams.load(f"{export}/physics.json", robot)
    policy = load_residual(f"{export}/residual.pt2")
    out = replay_trajectories(robot, [traj], ds.rate_hz, policy, physics=physics)
    return out["residual"].q[0][:n]


if __name__ == "__main__":
    main()
