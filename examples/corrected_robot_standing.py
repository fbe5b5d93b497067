"""The calibrated robot standing on the floor in a plain Newton scene, under a PD stance and a slow squat.

Loads ``wresdyn export``'s ``actuated.usda`` with a free base, adds a ground plane and steps it with Newton's
contact-capable ``SolverMuJoCo`` (MuJoCo C on the CPU, mujoco_warp on CUDA): identified physics in the model,
the drive path in ``model.actuators`` (PD, delay, effort clamping), the residual network every step through
:class:`~wresdyn.export.residual_torque.ResidualTorque`. Writes a USD animation with Newton's ``ViewerUSD``
(``usdview standing.usda`` plays it). ``--nominal`` runs the robot file as it was, for comparison.

    python examples/corrected_robot_standing.py runs/fit/export --seconds 4 --out standing.usda

Contacts: Newton's defaults for the shapes of the robot file and the ground plane (friction 1.0; SolverMuJoCo's
conversion of them to MuJoCo geoms, pyramidal cone, condim 3); the robot starts 5 mm above its standing height.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

SQUAT = {"hip_pitch": -1.0, "knee": 2.0, "ankle_pitch": -1.0}
"""Joint-name suffix -> multiple of the squat depth [rad] (a knee bend with the feet flat)."""


def build(usd_path: str, worlds: int = 1, device: str = "cpu"):
    """Newton model of ``worlds`` copies of the robot on a ground plane, and its contact solver."""
    import newton

    robot = newton.ModelBuilder()
    robot.add_usd(usd_path, floating=True, enable_self_collisions=False, load_visual_shapes=False)
    scene = newton.ModelBuilder()
    scene.replicate(robot, worlds)
    scene.add_ground_plane()
    model = scene.finalize(device=device)
    solver = newton.solvers.SolverMuJoCo(model, use_mujoco_cpu=device == "cpu" and worlds == 1,
                                         integrator="implicitfast", njmax=200, nconmax=100)
    return model, solver


def stand(model, state, clearance: float = 0.005) -> None:
    """Put each world's robot at rest with its lowest collision shape ``clearance`` [m] above the floor (z up)."""
    import newton

    newton.eval_fk(model, state.joint_q, state.joint_qd, state)
    body_q = state.body_q.numpy()
    shape_body, shape_tf = model.shape_body.numpy(), model.shape_transform.numpy()
    scale, kinds = model.shape_scale.numpy(), model.shape_type.numpy()
    lowest = np.inf
    for s in range(model.shape_count):
        b = int(shape_body[s])
        if b < 0:
            continue
        p, q = body_q[b, :3], body_q[b, 3:]
        centre = p + _rotate(q, shape_tf[s, :3])
        r = _rotate(q, _rotate(shape_tf[s, 3:], np.eye(3)))  # box axes in the world
        if int(kinds[s]) == int(newton.GeoType.BOX):
            lowest = min(lowest, centre[2] - np.abs(r[2] * scale[s]).sum())
        else:
            lowest = min(lowest, centre[2] - float(np.max(scale[s])))
    q = state.joint_q.numpy()
    starts = model.joint_q_start.numpy()
    for j, t in enumerate(model.joint_type.numpy()):
        if int(t) == int(newton.JointType.FREE):
            q[starts[j] + 2] += clearance - lowest
    state.joint_q.assign(q)
    state.joint_qd.zero_()
    newton.eval_fk(model, state.joint_q, state.joint_qd, state)


def _rotate(quat_xyzw, v):
    """Rotate vector(s) ``v`` (3,) or the columns of (3, 3) by a unit quaternion (x, y, z, w)."""
    x, y, z, w = quat_xyzw
    r = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    return r @ v


def tilt(quat_xyzw) -> np.ndarray:
    """Roll and pitch [rad] of a base orientation (x, y, z, w), z up."""
    x, y, z, w = quat_xyzw
    return np.array([np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y)),
                     np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))])


class Stance:
    """PD targets of a stance with a slow squat of ``depth`` [rad] (hip pitch; knee twice, ankle to keep the foot
    flat) and an ankle balance feedback on the base tilt: ankle pitch/roll targets ``gain · tilt + damping ·
    tilt rate``. The robot file's ankle gains (40 N m/rad per ankle) are below the ~200 N m/rad of gravity's
    toppling torque of a 35 kg body, so a PD stance alone tips over slowly; the feedback (gain 4: the calibrated
    ankles are weaker still, and gain 2 let it fall during the squat) multiplies their
    restoring torque by (1 + gain)."""

    def __init__(self, model, depth: float, period: float, gain: float = 4.0, damping: float = 0.2, dt: float = 0.002):
        self.depth, self.period, self.gain, self.damping, self.dt = depth, period, gain, damping, dt
        self.q_start = model.joint_q_start.numpy()
        self.size = model.joint_coord_count
        self.squat, self.ankle = [], []
        for j, label in enumerate(model.joint_label):
            name = label.rstrip("/").split("/")[-1]
            self.squat += [(int(self.q_start[j]), k) for suffix, k in SQUAT.items() if name.endswith(suffix)]
            if name.endswith("ankle_pitch"):
                self.ankle.append((int(self.q_start[j]), 1))
            elif name.endswith("ankle_roll"):
                self.ankle.append((int(self.q_start[j]), 0))
        self.prev = None

    def targets(self, t: float, base_quat) -> np.ndarray:
        """Joint targets (joint_q layout; free joints untouched) at time ``t`` [s]."""
        target = np.zeros(self.size, dtype=np.float32)
        phase = 0.5 * (1.0 - np.cos(2.0 * np.pi * t / self.period))
        for i, k in self.squat:
            target[i] = k * self.depth * phase
        angles = tilt(base_quat)
        rate = np.zeros(2) if self.prev is None else (angles - self.prev) / self.dt
        self.prev = angles
        feedback = self.gain * angles + self.damping * rate
        for i, axis in self.ankle:
            target[i] += feedback[axis]
        return target


def run(usd_path: str, seconds: float, out: str | None, nominal: bool = False, depth: float = 0.1,
        period: float = 4.0, dt: float = 0.002, fps: int = 50) -> dict:
    """Stand and squat for ``seconds``; returns the base height over time and whether the robot fell."""
    import newton
    import warp as wp

    from wresdyn.export.residual_torque import ResidualTorque

    model, solver = build(usd_path)
    s0, s1, control = model.state(), model.state(), model.control()
    stand(model, s0)
    residual = None if nominal else ResidualTorque.from_usd(usd_path, model, dt)
    acts = list(model.actuators)
    ast, ast_next = [a.state() for a in acts], [a.state() for a in acts]
    if residual is not None:
        residual.reset()
    viewer = None
    if out:
        viewer = newton.viewer.ViewerUSD(output_path=out, fps=fps, num_frames=None)
        viewer.set_model(model)
    root = next(j for j, t in enumerate(model.joint_type.numpy()) if int(t) == int(newton.JointType.FREE))
    z_index = int(model.joint_q_start.numpy()[root]) + 2
    heights, every = [], max(int(round(1.0 / (fps * dt))), 1)
    steps = int(round(seconds / dt))
    z0 = float(s0.joint_q.numpy()[z_index])
    stance = Stance(model, depth, period, dt=dt)
    for k in range(steps + 1):
        if viewer is not None and k % every == 0:
            viewer.begin_frame(k * dt)
            viewer.log_state(s0)
            viewer.end_frame()
        q = s0.joint_q.numpy()
        heights.append(float(q[z_index]))
        if k == steps:
            break
        target = stance.targets(k * dt, q[z_index + 1:z_index + 5])
        control.joint_target_q.assign(target)
        control.joint_f.zero_()
        for a, sa, sb in zip(acts, ast, ast_next):
            a.step(s0, control, sa, sb, dt=dt)
        if residual is not None:
            q_cmd = wp.to_torch(control.joint_target_q)[residual.q_index].cpu().numpy()
            residual.apply(s0, control, q_cmd)
        solver.step(s0, s1, control, None, dt)
        s0, s1 = s1, s0
        ast, ast_next = ast_next, ast
    if viewer is not None:
        viewer.close()
    h = np.array(heights)
    fell = bool(h.min() < 0.5 * z0 or not np.isfinite(h).all())
    return {"start_height": z0, "min_height": float(h.min()), "final_height": float(h[-1]), "fell": fell,
            "steps": steps, "heights": h}


def main() -> None:
    import torch
    import warp as wp

    wp.config.quiet = True
    torch.set_num_threads(1)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("export", help="folder written by `wresdyn export`")
    p.add_argument("--seconds", type=float, default=4.0)
    p.add_argument("--depth", type=float, default=0.1, help="squat depth: hip pitch angle [rad] (knee twice)")
    p.add_argument("--out", default="standing.usda", help="USD animation to write ('' for none)")
    p.add_argument("--nominal", action="store_true", help="the robot file as it was (no export), for comparison")
    args = p.parse_args()
    usd = f"{args.export}/actuated.usda"
    if args.nominal:
        usd = json.loads((Path(args.export) / "export.json").read_text())["robot_file"]
        if not Path(usd).exists():
            from wresdyn.paths import REPO

            usd = str(REPO / usd)
    r = run(usd, args.seconds, args.out or None, args.nominal, args.depth)
    print(f"{'nominal' if args.nominal else 'calibrated'} robot on the floor, {args.seconds:g} s: base height "
          f"{r['start_height']:.3f} m at the start, min {r['min_height']:.3f}, end {r['final_height']:.3f}; "
          f"{'FELL' if r['fell'] else 'standing'}" + (f"; wrote {args.out}" if args.out else ""))


if __name__ == "__main__":
    main()
