"""Floating-base stance throughput: env-steps/s of ``Simulator(..., solver="mujoco", ground=True)``.

The project humanoid (``scenes/humanoid.usda``, free base, 21 DoF) stands on the floor from
:func:`~wresdyn.robot.ground.standing_state` holding its neutral pose under PD, dt = 2 ms; one env-step is one
world advanced by one dt. On the CPU one world runs on MuJoCo C through Newton's ``SolverMuJoCo``, several on
mujoco_warp on Warp's CPU device (Newton's MuJoCo C backend holds one world). For reference the last row steps the
MuJoCo C real robot (:class:`~wresdyn.data.real_robot.RealRobot`, nominal) directly, without Newton. Every figure
is the best of ``--repeats`` timed loops of ``--steps`` from the standing start, after a warm-up (compilation
excluded).

    python benchmarks/speed/floating_base.py                      # CPU: 1 and 16 worlds
    python benchmarks/speed/floating_base.py --device cuda:0 --worlds 1024 4096
"""

from __future__ import annotations

import argparse
import time


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--worlds", type=int, nargs="+", default=[1, 16])
    ap.add_argument("--device", default="cpu")
    ap.add_argument("--steps", type=int, default=250, help="steps per timed loop")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1, help="torch threads")
    args = ap.parse_args()

    import numpy as np
    import torch

    torch.set_num_threads(args.threads)
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.robot.description import load_robot
    from wresdyn.robot.ground import standing_state
    from wresdyn.sim import Simulator

    robot = load_robot("scenes/humanoid.usda", base="floating")
    start = standing_state(robot)
    print(f"{robot.source.name}: {robot.n_dof} DoF, floating base, dt 2 ms, {args.device}, torch threads {args.threads}")
    for w in args.worlds:
        sim = Simulator(robot, w, 0.002, solver="mujoco", ground=True, device=args.device)
        backend = "mujoco_warp" if not sim.solver.use_mujoco_cpu else "MuJoCo C"
        def per_world(a, sim=sim, w=w):
            return torch.as_tensor(np.asarray(a), dtype=torch.float32, device=sim.device).expand(w, -1).contiguous()

        start_state = (per_world(start.base_pose), per_world(start.base_twist), per_world(start.q), per_world(start.qd))
        target = per_world(robot.q0)
        sim.set_full_state(None, *start_state)
        for _ in range(10):  # compile, allocate, capture
            sim.step(target)
        best = 0.0
        for _ in range(args.repeats):
            sim.set_full_state(None, *start_state)  # each loop a fresh stance (the humanoid tips over after ~3 s)
            if sim.device.type == "cuda":
                torch.cuda.synchronize(sim.device)
            t0 = time.perf_counter()
            for _ in range(args.steps):
                sim.step(target)
            z = sim.base_pose[:, 2]  # reads back: waits for the device
            best = max(best, w * args.steps / (time.perf_counter() - t0))
        print(f"Simulator {w:>5} worlds ({backend:<11}): {best:>10,.0f} env-steps/s   base height "
              f"{float(z.min()):.4f}-{float(z.max()):.4f} m")
    real = RealRobot(robot)
    best = 0.0
    for _ in range(args.repeats):
        real.reset(start)
        t0 = time.perf_counter()
        for _ in range(args.steps):
            real.step(robot.q0)
        best = max(best, args.steps / (time.perf_counter() - t0))
    print(f"RealRobot.step    1 world  (MuJoCo C)   : {best:>10,.0f} env-steps/s   base height "
          f"{real.state.base_pose[2]:.4f} m")


if __name__ == "__main__":
    main()
