"""What the servo goal profile costs an identification iteration on a dataset's training runs: the bank's targets with
the delay and the goal acceleration differentiable (the whole table profiled each iteration), 32 windows of 128 steps
drawn, and the backward pass to both; every repeat timed (the first includes Warp's kernel load, if any).

    OMP_NUM_THREADS=1 python benchmarks/real/servo_profile_cost.py DATA.npz --gains scenes/so101/servo.toml [--samples N]

Times the ``wresdyn`` on ``sys.path`` first: ``PYTHONPATH=CHECKOUT`` compares two checkouts on the same data.
"""

import argparse
import statistics
import time

import numpy as np
import torch

import wresdyn
from wresdyn.data.loading import load_data
from wresdyn.sim import TrajectoryBank
from wresdyn.sim.bank import servo_goal_accel


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data")
    p.add_argument("--gains", default=None)
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--samples", type=int, default=0, help="cut every run to its first SAMPLES (0: whole runs)")
    args = p.parse_args()
    torch.set_num_threads(1)
    ds, robot = load_data(args.data, None, args.gains)
    train = ds.split("train")
    if args.samples:
        train = [type("Run", (), {k: getattr(t, k)[:args.samples] for k in ("q", "qd", "qdd", "q_cmd")}) for t in train]
    dt = 1.0 / ds.rate_hz
    bank = TrajectoryBank(train, torch.device("cpu"))
    accel0 = servo_goal_accel(robot, None, dt, bank.device)
    if accel0 is None:
        raise SystemExit("the robot has no servo drives (pass --gains)")
    rng = np.random.default_rng(0)
    times = []
    for _ in range(args.repeats):
        delay = torch.full((robot.n_dof,), 2.5, requires_grad=True)
        accel = accel0.clone().requires_grad_()
        t0 = time.perf_counter()
        bank.set_command_path(delay, accel)
        w = bank.sample(rng, 32, 128)
        w.target.square().sum().backward()
        times.append(time.perf_counter() - t0)
    rows = int(bank.length.sum())
    print(f"wresdyn at {wresdyn.__file__}")
    print(f"{len(train)} training runs, {rows} samples at {ds.rate_hz:g} Hz, {robot.n_dof} joints: profile forward + "
          f"backward per iteration {statistics.median(times):.3f} s (median of "
          + ", ".join(f"{t:.3f}" for t in times) + ")")
    print(f"grad delay {delay.grad.numpy().round(3)}  grad goal_accel {accel.grad.numpy()}")


if __name__ == "__main__":
    main()
