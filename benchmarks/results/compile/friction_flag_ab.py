"""One process, one adjoint module: CPU-seconds of a Tape rollout forward + backward (humanoid, the bench's inputs, W
worlds x 32 steps, robot-file physics without friction) with SolverReplay.friction_grad off (the solve skipped) and on
(the solve run, as before this change), interleaved, 5 rounds of best-of-5."""
import sys, time
import numpy as np
import warp as wp
wp.config.quiet = True
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim.solver_replay import SolverReplay
w, T = int(sys.argv[1]), 32
robot = load_robot(DEFAULT_ROBOT)
span = np.where(np.isfinite(robot.upper - robot.lower), robot.upper - robot.lower, 2.0)
lo = np.where(np.isfinite(robot.lower), robot.lower, -1.0); hi = np.where(np.isfinite(robot.upper), robot.upper, 1.0)
q0 = np.clip(np.zeros(robot.n_dof), lo + 0.3 * span, hi - 0.3 * span); amp = np.minimum(0.2, 0.12 * span)
model = robot.build_model(w, "cpu", requires_grad=True)
s = SolverReplay(model, friction_grad=False)
n = s.tree.dofs_per_world
t = np.arange(T)[:, None, None] * 0.002; f = np.linspace(0.3, 1.0, n)[None, None, :]
targ = (q0 + amp * np.sin(2 * np.pi * f * t + np.arange(w)[None, :, None] * 0.1)).astype(np.float32)
tq = wp.array(targ[:, :, robot.qd_index.argsort()], dtype=float, requires_grad=True)
qi = np.zeros((T + 1, w, n), np.float32); qi[0] = q0[robot.q_index.argsort()] + 0.1
q = wp.array(qi, dtype=float, requires_grad=True); qd = wp.zeros((T + 1, w, n), dtype=float, requires_grad=True)
jf = wp.zeros((T, w, n), dtype=float, requires_grad=True)
seed = np.zeros((T + 1, w, n), np.float32); seed[T] = 1.0
seed = wp.array(seed)

def run():
    tape = wp.Tape()
    with tape:
        s.rollout(q, qd, tq, 0.002, joint_f=jf)
    c0 = time.process_time()
    tape.backward(grads={q: seed})
    back = time.process_time() - c0
    out = [q.grad.numpy()[0].copy(), tq.grad.numpy().copy(), jf.grad.numpy().copy()]
    tape.zero()
    return back, out

res = {False: [], True: []}
outs = {}
for r in range(5):
    for on in (False, True):
        s.friction_grad = on
        run()
        best = min(run()[0] for _ in range(5))
        res[on].append(w * T / best / 1e3)
        outs[on] = run()[1]
same = all(np.array_equal(a, b) for a, b in zip(outs[False], outs[True]))
for on in (False, True):
    print(f"friction_grad={on}: backward pass (adjoint launches) of {w} worlds x {T} steps, k env-steps per CPU-second, "
          f"5 rounds of best-of-5: {', '.join(f'{x:.1f}' for x in res[on])}; median {np.median(res[on]):.1f}")
print(f"gradients to q0, targets, joint_f bit-equal between the two: {same}")
