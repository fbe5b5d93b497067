"""Torch operators of one gradient-fit iteration by name, per step of its windows: what the iteration's torch kernels
are (on CUDA most operators here are one kernel each; views such as ``t``, ``view``, ``select`` are none).

    python benchmarks/speed/gradfit_torch_ops.py --horizon 16 --windows 8
    python benchmarks/speed/gradfit_torch_ops.py --horizon 16 --windows 8 --fused   # GradFitConfig.fused_network

The shipped humanoid (21 DoF) and data, the gradient fit's defaults at one window length, on the CPU: one iteration
warms up, the next runs under torch's profiler. Counted: the operators called from Python or autograd (an operator
another one calls is not counted again), and of them those that launch work on CUDA (:data:`NO_KERNEL` are not);
beside them the Warp memsets (``wp.array.zero_`` calls, a ``Memset`` on CUDA each) are counted.
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

NO_KERNEL = frozenset("aten::" + n for n in (
    "t", "view", "select", "alias", "narrow", "detach", "expand", "unsqueeze", "squeeze", "slice", "transpose",
    "as_strided", "lift_fresh", "empty", "to", "item"))
"""Operators that launch no kernel on CUDA: views, uninitialised allocations, a cast to the tensor's own device and
dtype (the rollout's ``.to(sim.device)``), and host reads (the CPU's Adam step count; on CUDA the fit keeps it on the
device)."""


def main() -> None:
    import torch
    import warp as wp
    from torch.profiler import ProfilerActivity, profile

    from wresdyn.data.dataset import load_dataset
    from wresdyn.fit.gradfit import GradFitConfig, _FitLearner
    from wresdyn.learn.window_fit import start_window_fit
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--horizon", type=int, default=16, help="window length [steps]")
    p.add_argument("--windows", type=int, default=8)
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--fused", action="store_true", help="the fused MLP path and fused Adam (fused_network)")
    args = p.parse_args()
    wp.config.quiet = True
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset(args.data, robot=robot)
    h = args.horizon
    cfg = GradFitConfig(windows=args.windows, horizon_curriculum=(h,), iterations=4, fused_network=args.fused)
    rng, train, dt = start_window_fit(cfg, data)
    learner = _FitLearner(robot, data, cfg, None, rng, train, dt, print)
    learner.step(0, h, cfg.lr)  # loads the kernels
    memsets = _count_calls(wp.array, "zero_")
    with profile(activities=[ProfilerActivity.CPU]) as prof:
        learner.step(1, h, cfg.lr)
    zeroed = memsets()
    events = [e for e in prof.events() if e.name.startswith("aten::")]
    top = [e for e in events if e.cpu_parent is None or not e.cpu_parent.name.startswith("aten::")]
    count = collections.Counter(e.name for e in top)
    total = sum(count.values())
    kernels = sum(c for name, c in count.items() if name not in NO_KERNEL)
    print(f"humanoid {robot.n_dof} DoF, {args.windows} windows, H = {h}, fused_network {args.fused}: {total} "
          f"operators in one iteration, {total / h:.1f} per step; {kernels} ({kernels / h:.1f} per step) that "
          "launch work on CUDA (views, empty allocations, same-device casts and host reads excluded)")
    print(f"Warp memsets (array.zero_): {zeroed} in one iteration, {zeroed / h:.2f} per step")
    print("| operator | count | per step | a kernel on CUDA |")
    print("|---|---|---|---|")
    for name, c in count.most_common():
        print(f"| {name} | {c} | {c / h:.2f} | {'no' if name in NO_KERNEL else 'yes'} |")


def _count_calls(owner, name: str):
    """Count the calls of ``owner.name`` from now on (a wrapper that calls the original); returns a function that puts
    the original back and gives the count."""
    original, calls = getattr(owner, name), [0]

    def counted(*args, **kwargs):
        calls[0] += 1
        return original(*args, **kwargs)

    setattr(owner, name, counted)

    def stop() -> int:
        setattr(owner, name, original)
        return calls[0]
    return stop


if __name__ == "__main__":
    main()
