"""CPU-seconds (process time, 1 thread) of SolverReplay's rollout on the humanoid with the bench's inputs: the fused
forward (W worlds x 200 steps) and a Tape forward + backward (W worlds x 32 steps, gradients to the states, targets and
joint_f only, as residual learning and `wresdyn bench` take them); best and median of 7; a checksum of the results."""
import hashlib, sys, time
import numpy as np
import warp as wp
wp.config.quiet = True
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim.solver_replay import SolverReplay
label, w = sys.argv[1], int(sys.argv[2])
robot = load_robot(DEFAULT_ROBOT)
span = np.where(np.isfinite(robot.upper - robot.lower), robot.upper - robot.lower, 2.0)
lo = np.where(np.isfinite(robot.lower), robot.lower, -1.0); hi = np.where(np.isfinite(robot.upper), robot.upper, 1.0)
q0 = np.clip(np.zeros(robot.n_dof), lo + 0.3 * span, hi - 0.3 * span); amp = np.minimum(0.2, 0.12 * span)
for mode, T in (("forward", 200), ("forward+backward", 32)):
    grad = mode != "forward"
    model = robot.build_model(w, "cpu", requires_grad=grad)
    kw = {"friction_grad": False} if grad and "friction_grad" in SolverReplay.__init__.__code__.co_varnames else {}
    s = SolverReplay(model, **kw)
    n = s.tree.dofs_per_world
    t = np.arange(T)[:, None, None] * 0.002; f = np.linspace(0.3, 1.0, n)[None, None, :]
    targ = (q0 + amp * np.sin(2 * np.pi * f * t + np.arange(w)[None, :, None] * 0.1)).astype(np.float32)
    tq = wp.array(targ[:, :, robot.qd_index.argsort()], dtype=float, requires_grad=grad)
    qi = np.zeros((T + 1, w, n), np.float32); qi[0] = q0[robot.q_index.argsort()] + 0.1
    q = wp.array(qi, dtype=float, requires_grad=grad); qd = wp.zeros((T + 1, w, n), dtype=float, requires_grad=grad)
    jf = wp.zeros((T, w, n), dtype=float, requires_grad=grad)
    seed = np.zeros((T + 1, w, n), np.float32); seed[T] = 1.0
    seed = wp.array(seed)

    def run():
        if not grad:
            s.rollout(q, qd, tq, 0.002)
            return
        tape = wp.Tape()
        with tape:
            s.rollout(q, qd, tq, 0.002, joint_f=jf)
        tape.backward(grads={q: seed})
        tape.zero()
    run()
    times = []
    for _ in range(7):
        c0 = time.process_time(); run(); times.append(time.process_time() - c0)
    if grad:
        tape = wp.Tape()
        with tape:
            s.rollout(q, qd, tq, 0.002, joint_f=jf)
        tape.backward(grads={q: seed})
        data = q.grad.numpy()[0].tobytes() + qd.grad.numpy()[0].tobytes() + tq.grad.numpy().tobytes() + jf.grad.numpy().tobytes()
    else:
        data = q.numpy().tobytes() + qd.numpy().tobytes()
    print(f"{label}: {mode}, {w} worlds x {T} steps: {w*T/min(times)/1e3:.1f}k env-steps per CPU-second (best of 7), "
          f"median {w*T/np.median(times)/1e3:.1f}k; results sha256 {hashlib.sha256(data).hexdigest()[:12]}", flush=True)
