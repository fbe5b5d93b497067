"""SolverReplay on a CUDA device: parity with MuJoCo C and gradients against the CPU build (issue 6).

    python benchmarks/fidelity/check_device.py [--device cuda:0]

Prints the 2 s trajectory error against MuJoCo C ``implicitfast`` on the project humanoid (the CPU
figure is in tests/sim/test_solver_replay.py), the difference between the device's and the CPU's
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

    # the simulation layer: Simulator.step replayed from CUDA graphs against plain launches and the CPU, with a
    # torque residual, a residual that pushes some worlds past a limit, and a state reset in between
    import torch

    from wresdyn.sim import Simulator

    qs = {}
    for dev, graph in ((args.device, True), (args.device, False), ("cpu", False)):
        sim = Simulator(robot, w, DT, device=dev, graph=graph)
        q0 = torch.as_tensor(np.tile(center, (w, 1)), dtype=torch.float32, device=sim.device)
        sim.set_state(None, q0, torch.zeros_like(q0))
        tau = torch.zeros_like(q0)
        tau[:, 0] = torch.linspace(-2.0, 2.0, w, device=sim.device)
        out = []
        for k in range(200):
            if k == 100:  # a reset of one world mid-run, as the PPO environment does
                sim.set_state(torch.tensor([1], device=sim.device), q0[:1], torch.zeros_like(q0[:1]))
            target = torch.as_tensor(np.tile(cmd[k], (w, 1)), dtype=torch.float32, device=sim.device)
            q, _ = sim.step(target, tau)
            out.append(q.cpu().numpy())
        qs[(dev, graph)] = np.stack(out)
    # the differentiable path (the gradient fit): a rollout with a torque residual through Simulator.step_diff
    from wresdyn.sim import Window, rollout

    grads = {}
    for dev in (args.device, "cpu"):
        sim = Simulator(robot, w, DT, device=dev, requires_grad=True)
        t = torch.as_tensor(cmd[:9], dtype=torch.float32, device=sim.device)
        q0 = torch.as_tensor(center, dtype=torch.float32, device=sim.device)
        zeros = torch.zeros(w, 9, robot.n_dof, device=sim.device)
        window = Window(q=q0.expand(w, 9, -1).contiguous(), qd=zeros.clone(), qdd=zeros.clone(),
                        cmd=t[:8].expand(w, 8, -1).contiguous(), target=t[:8].expand(w, 8, -1).contiguous(),
                        length=torch.full((w,), 8, device=sim.device))
        res = torch.randn(w, 8, robot.n_dof, generator=torch.Generator().manual_seed(0)).to(sim.device)
        res.requires_grad_()
        r = rollout(sim, window, residual=res, kind="torque", grad=True)
        (r.q[:, -1].sum() + r.qd[:, -1].sum()).backward()
        grads[dev] = res.grad.cpu().numpy()
    g_dev, g_cpu = grads[args.device], grads["cpu"]
    print(f"Simulator.step_diff rollout (8 steps, torque residual): {args.device} vs cpu d(sum q_T + qd_T)/d tau "
          f"max rel diff = {np.abs(g_dev - g_cpu).max() / np.abs(g_cpu).max():.2e}")
    print(f"Simulator.step, {w} worlds x 200 steps: CUDA graph vs launches max |dq| = "
          f"{np.abs(qs[(args.device, True)] - qs[(args.device, False)]).max():.2e} rad, vs cpu "
          f"{np.abs(qs[(args.device, True)] - qs[('cpu', False)]).max():.2e} rad")


if __name__ == "__main__":
    main()
