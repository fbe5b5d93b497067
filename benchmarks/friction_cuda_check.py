"""SolverReplay's soft friction law on CUDA against the CPU (the same generated source, float32): one hinge at 0.5
and 1.5 mu, the humanoid multisine with friction on every joint. Needs a GPU: ``python benchmarks/friction_cuda_check.py``."""
import sys
import time

sys.path.insert(0, "tests")
import numpy as np
import warp as wp

wp.config.quiet = True
import pathlib
import tempfile

from test_friction import DT, HINGE_URDF, MU

from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim.parity import multisine_command
from wresdyn.sim.solver_replay import SolverReplay


def roll(robot, q0, cmd, tau, device):
    solver = SolverReplay(robot.build_model(1, device))
    t_len, n = cmd.shape
    q = np.zeros((t_len + 1, 1, n), np.float32); q[0, 0] = q0
    qa, qda = wp.array(q, device=device), wp.array(np.zeros_like(q), device=device)
    f = None if tau is None else wp.array(tau[:, None].astype(np.float32), device=device)
    solver.rollout(qa, qda, wp.array(cmd[:, None].astype(np.float32), device=device), DT, joint_f=f)
    return qa.numpy()[:, 0]

p = pathlib.Path(tempfile.mkdtemp()) / "hinge.urdf"; p.write_text(HINGE_URDF)
hinge = load_robot(p, gains={"joint": [{"match": "*", "kp": 0.0, "kd": 0.0, "friction": MU, "armature": 0.01}]})
for ratio in (0.5, 1.5):
    tau, cmd = np.full((500, 1), ratio * MU), np.zeros((500, 1))
    t0 = time.time(); a = roll(hinge, np.zeros(1), cmd, tau, "cpu"); b = roll(hinge, np.zeros(1), cmd, tau, "cuda:0")
    print(f"hinge {ratio} mu: q(1 s) cpu {a[-1,0]:.6f} cuda {b[-1,0]:.6f}, max |cpu - cuda| {np.abs(a-b).max():.2e} ({time.time()-t0:.0f} s)", flush=True)
plain = load_robot(DEFAULT_ROBOT)
robot = load_robot(DEFAULT_ROBOT, gains={"joint": [{"match": n, "friction": 0.1 * float(e)} for n, e in zip(plain.joint_names, plain.effort)]})
cmd = multisine_command(robot, 2.0, DT)
t0 = time.time(); a = roll(robot, cmd[0], cmd, None, "cpu"); b = roll(robot, cmd[0], cmd, None, "cuda:0")
print(f"humanoid multisine, friction 0.1 x effort: max |cpu - cuda| {np.abs(a-b).max():.2e} rad, mean {np.abs(a-b).mean():.2e} ({time.time()-t0:.0f} s)", flush=True)
