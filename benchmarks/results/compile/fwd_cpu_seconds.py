"""CPU seconds per forward rollout step of SolverReplay on the humanoid (process time, robust to other load)."""
import sys, time
import numpy as np
import warp as wp
wp.config.quiet = True
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim.solver_replay import SolverReplay
robot = load_robot(DEFAULT_ROBOT)
w, T = 128, 200
for kw in [dict(a) for a in eval(sys.argv[1])]:
    model = robot.build_model(w, "cpu")
    label = dict(kw)
    if kw.pop("friction", False):
        model.joint_friction.assign(np.full(model.joint_dof_count, 0.3, np.float32))
    s = SolverReplay(model, **kw)
    n = s.tree.dofs_per_world
    span = np.where(np.isfinite(robot.upper - robot.lower), robot.upper - robot.lower, 2.0)
    lo = np.where(np.isfinite(robot.lower), robot.lower, -1.0); hi = np.where(np.isfinite(robot.upper), robot.upper, 1.0)
    q0 = np.clip(np.zeros(n), lo + 0.3 * span, hi - 0.3 * span); amp = np.minimum(0.2, 0.12 * span)
    t = np.arange(T)[:, None, None] * 0.002; f = np.linspace(0.3, 1.0, n)[None, None, :]
    targ = (q0 + amp * np.sin(2 * np.pi * f * t + np.arange(w)[None, :, None] * 0.1)).astype(np.float32)
    tq = wp.array(targ[:, :, robot.qd_index.argsort()], dtype=float)
    qi = np.zeros((T + 1, w, n), np.float32); qi[0] = q0[robot.q_index.argsort()] + 0.1
    q = wp.array(qi, dtype=float); qd = wp.zeros((T + 1, w, n), dtype=float)
    s.rollout(q, qd, tq, 0.002)
    best, wall = [], []
    for _ in range(5):
        c0 = time.process_time(); w0 = time.perf_counter(); s.rollout(q, qd, tq, 0.002); best.append(time.process_time() - c0); wall.append(time.perf_counter() - w0)
    print(f"{sys.argv[2]} SolverReplay(**{kw}), joint_friction {0.3 if label.get('friction') else 0.0}: {w*T/min(best)/1e3:.1f}k env-steps per CPU-second (best of 5, {w} worlds x {T} steps; wall best {w*T/min(wall)/1e3:.1f}k/s)", flush=True)
