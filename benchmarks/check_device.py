"""SolverReplay on a CUDA device: parity with MuJoCo C and gradients against the CPU build (issue 6).

    python benchmarks/check_device.py [--device cuda:0]

Prints the 2 s trajectory error against MuJoCo C ``implicitfast`` on the project humanoid (the CPU
figure is in tests/test_solver_replay.py), the difference between the device's and the CPU's
trajectories and Tape gradients, and that the step() API matches the fused rollout on the device.
"""

import argparse

import numpy as np
import warp as wp

from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.robot.mujoco_model import build_mujoco
from wresdyn.sim.solver_replay import SolverReplay

DT = 0.002


def main() -> None:
    import mujoco

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cuda:0")
    args = p.parse_args()
    wp.config.quiet = True
    robot = load_robot(DEFAULT_ROBOT)
    n, w, t_len = robot.n_dof, 4, 1000
    span = robot.upper - robot.lower
    center = np.clip(np.zeros(n), robot.lower + 0.3 * span, robot.upper - 0.3 * span)
    freq = np.random.default_rng(0).uniform(0.3, 1.0, n)
    cmd = center + np.minimum(0.2, 0.12 * span) * np.sin(2 * np.pi * freq * np.arange(t_len)[:, None] * DT)

    m = build_mujoco(robot, DT, "implicitfast")
    d = mujoco.MjData(m)
    d.qpos[:] = center
    ref = [d.qpos.copy()]
    for c in cmd:
        d.ctrl[:] = c
        mujoco.mj_step(m, d)
        ref.append(d.qpos.copy())
    ref = np.array(ref)

    def run(device, steps, grad):
        solver = SolverReplay(robot.build_model(w, device, requires_grad=grad))
        q = np.zeros((steps + 1, w, n), np.float32)
        q[0] = center
        qa = wp.array(q, device=device, requires_grad=grad)
        qda = wp.zeros((steps + 1, w, n), device=device, requires_grad=grad)
        tq = wp.array(np.repeat(cmd[:steps, None], w, axis=1).astype(np.float32), device=device, requires_grad=grad)
        if not grad:
            solver.rollout(qa, qda, tq, DT)
            return solver, qa.numpy()
        tape = wp.Tape()
        with tape:
            solver.rollout(qa, qda, tq, DT)
        seed = np.zeros((steps + 1, w, n), np.float32)
        seed[steps] = 1.0
        tape.backward(grads={qa: wp.array(seed, device=device)})
        return solver, qa.numpy(), qa.grad.numpy()[0], tq.grad.numpy()

    solver, q_dev = run(args.device, t_len, False)
    _, q_cpu = run("cpu", t_len, False)
    err = np.abs(q_dev[:, 0] - ref).max()
    print(f"{args.device}: 2 s humanoid trajectory vs MuJoCo C implicitfast: max |q err| = {err:.2e} rad")
    print(f"{args.device} vs cpu trajectory: max |dq| = {np.abs(q_dev - q_cpu).max():.2e} rad")

    model = solver.model
    s0, s1, ctrl = model.state(), model.state(), model.control()
    s0.joint_q.assign(np.tile(center, w).astype(np.float32))
    for k in range(100):
        ctrl.joint_target_q.assign(np.tile(cmd[k], w).astype(np.float32))
        solver.step(s0, s1, ctrl, None, DT)
        s0, s1 = s1, s0
    print(f"{args.device} step() API vs fused rollout after 100 steps: max |dq| = "
          f"{np.abs(s0.joint_q.numpy().reshape(w, n) - q_dev[100]).max():.2e} rad")

    _, _, g_q0, g_tq = run(args.device, 32, True)
    _, _, c_q0, c_tq = run("cpu", 32, True)
    rel = max(np.abs(g_q0 - c_q0).max() / np.abs(c_q0).max(), np.abs(g_tq - c_tq).max() / np.abs(c_tq).max())
    print(f"{args.device} vs cpu Tape gradients (32 steps, d sum q_T / d q_0 and d / d target_q): "
          f"max rel diff = {rel:.2e}")


if __name__ == "__main__":
    main()
