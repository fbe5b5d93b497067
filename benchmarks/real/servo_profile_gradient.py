"""Whether the goal profile's gradient in the goal acceleration means anything on a dataset's runs: the pathwise
derivative (:func:`wresdyn.sim.goal_profile.profile_goals`' adjoint, float64) of L = sum |goal - command|² over the
first N samples of every training run, per joint, against central differences of L at steps of 1 % and 0.1 % of
a_max, for growing N.

    OMP_NUM_THREADS=1 python benchmarks/real/servo_profile_gradient.py DATA.npz --gains scenes/so101/servo.toml
"""

import argparse
import warnings

import numpy as np
import torch

from wresdyn.data.loading import load_data
from wresdyn.sim.bank import servo_goal_accel
from wresdyn.sim.goal_profile import profile_goals


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data")
    p.add_argument("--gains", default=None)
    p.add_argument("--samples", default="100,500,2000,8000")
    args = p.parse_args()
    torch.set_num_threads(1)
    warnings.simplefilter("ignore")
    ds, robot = load_data(args.data, None, args.gains)
    a0 = servo_goal_accel(robot, None, 1.0 / ds.rate_hz, "cpu").double()
    np.set_printoptions(precision=3, linewidth=150, floatmode="maxprec")
    print(f"a_max {a0[0].item():.4g} rad/step² on every joint" if bool((a0 == a0[0]).all()) else f"a_max {a0.numpy()}")
    for n in (int(s) for s in args.samples.split(",")):
        runs = [t.q_cmd[:n] for t in ds.split("train") if len(t.q_cmd) >= n]
        cmd = torch.tensor(np.concatenate(runs), dtype=torch.float64)
        first = torch.tensor(np.repeat(np.arange(len(runs)) * n, n))

        def loss(a):
            return ((profile_goals(cmd, first, a) - cmd) ** 2).sum(0)

        a = a0.clone().requires_grad_()
        loss(a).sum().backward()
        print(f"N={n:5d} ({len(runs)} runs)  pathwise {a.grad.numpy()}")
        for rel in (1e-2, 1e-3):
            fd = (loss(a0 * (1 + rel)) - loss(a0 * (1 - rel))) / (2 * rel * a0)
            print(f"{'':20s}central {rel:g}   {fd.numpy()}")


if __name__ == "__main__":
    main()
