"""SolverReplay's soft friction law on CUDA against the CPU (the same generated source, float32): one hinge at 0.5
and 1.5 mu, the humanoid multisine with friction on every joint. Needs a GPU:

    python benchmarks/fidelity/friction_cuda_check.py
"""

from __future__ import annotations

import tempfile
import time

import numpy as np


def main() -> None:
    import warp as wp
    from hinge import MU, make_hinge, newton_rollout

    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim.parity import multisine_command

    wp.config.quiet = True
    hinge = make_hinge(tempfile.mkdtemp())
    for ratio in (0.5, 1.5):
        tau, cmd = np.full((500, 1), ratio * MU), np.zeros((500, 1))
        t0 = time.time()
        a, _ = newton_rollout(hinge, np.zeros(1), cmd, tau)
        b, _ = newton_rollout(hinge, np.zeros(1), cmd, tau, device="cuda:0")
        print(f"hinge {ratio} mu: q(1 s) cpu {a[-1, 0]:.6f} cuda {b[-1, 0]:.6f}, max |cpu - cuda| "
              f"{np.abs(a - b).max():.2e} ({time.time() - t0:.0f} s)", flush=True)
    plain = load_robot(DEFAULT_ROBOT)
    robot = load_robot(DEFAULT_ROBOT, gains={"joint": [
        {"match": n, "friction": 0.1 * float(e)} for n, e in zip(plain.joint_names, plain.effort)]})
    cmd = multisine_command(robot, 2.0, 0.002)
    t0 = time.time()
    a, _ = newton_rollout(robot, cmd[0], cmd)
    b, _ = newton_rollout(robot, cmd[0], cmd, device="cuda:0")
    print(f"humanoid multisine, friction 0.1 x effort: max |cpu - cuda| {np.abs(a - b).max():.2e} rad, "
          f"mean {np.abs(a - b).mean():.2e} ({time.time() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
