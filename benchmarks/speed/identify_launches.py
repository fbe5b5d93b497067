"""Launches of one identification Adam step, counted on the CPU: torch's operators (those that are a kernel on CUDA)
and Warp's launches, by window length; what a CUDA graph of the step (``SysIdConfig.cuda_graph``) turns into one
launch.

    python benchmarks/speed/identify_launches.py                    # H = 16 32 64 128, the default (fused) replay
    python benchmarks/speed/identify_launches.py --horizons 64 --stepped

The shipped humanoid (21 DoF) and data, :class:`~wresdyn.identify.sysid_config.SysIdConfig`'s defaults (32 windows),
built as :func:`~wresdyn.identify.sysid.identify` builds it, at iterations after the effort limit has joined the fit
(all fields with gradients). Per window length one step warms up, the next runs under ``torch.profiler`` with Warp's
launches counted: the solver's recorded launch plans (:class:`~wresdyn.sim.solver_replay.launch.LaunchPlans`, one
call per kernel launch) and direct ``wp.launch`` calls. Torch operators are counted as ``gradfit_torch_ops.py``
counts them (top-level ``aten::`` operators, views, empty allocations, casts to the own device and host reads not
being kernels; a cast that copies, ``aten::to (copy)``, is one).
"""

from __future__ import annotations

import argparse
import collections
from pathlib import Path

from gradfit_torch_ops import NO_KERNEL as GRADFIT_NO_KERNEL  # the same folder

ROOT = Path(__file__).resolve().parents[2]

NO_KERNEL = GRADFIT_NO_KERNEL | frozenset("aten::" + n for n in (
    "_local_scalar_dense", "is_nonzero", "empty_like", "reshape", "flatten", "expand_as", "view_as", "numpy_T",
    "resolve_conj", "resolve_neg"))
"""Operators that launch no kernel on CUDA: ``gradfit_torch_ops.py``'s, with the other views and host reads met
here."""


def count(learner, it: int, h: int) -> dict:
    """Torch operators and Warp launches of ``learner.step(it, h, lr)``."""
    import torch
    import warp as wp
    from torch.profiler import ProfilerActivity, profile

    from wresdyn.sim.solver_replay.launch import LaunchPlans

    warp_launches = collections.Counter()
    execute, launch = LaunchPlans._execute, wp.launch

    def counted_execute(self, plan):
        warp_launches["solver plan"] += len(plan[0])
        return execute(self, plan)

    def counted_launch(*a, **k):
        if not k.get("record_cmd"):
            warp_launches["wp.launch"] += 1
        return launch(*a, **k)

    LaunchPlans._execute, wp.launch = counted_execute, counted_launch
    try:
        with profile(activities=[ProfilerActivity.CPU]) as prof:
            learner.step(it, h, learner.cfg.lr)
    finally:
        LaunchPlans._execute, wp.launch = execute, launch
    events = [e for e in prof.events() if e.name.startswith("aten::")]
    top = [e for e in events if e.cpu_parent is None or not e.cpu_parent.name.startswith("aten::")]
    # a cast that copies (another dtype or device) is a kernel: aten::to then calls _to_copy
    ops = collections.Counter("aten::to (copy)" if e.name == "aten::to" and any(
        c.name == "aten::_to_copy" for c in e.cpu_children) else e.name for e in top)
    kernels = sum(c for name, c in ops.items() if name not in NO_KERNEL)
    return {"torch_ops": sum(ops.values()), "torch_kernels": kernels, "warp": dict(warp_launches), "ops": ops}


def main() -> None:
    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.identify.sysid import IdentifyLearner, SysIdConfig
    from wresdyn.learn.window_fit import start_window_fit
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--horizons", type=int, nargs="+", default=[16, 32, 64, 128])
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--stepped", action="store_true", help="SysIdConfig.fused false: one launch per step")
    p.add_argument("--ops", action="store_true", help="list the torch operators of the last length")
    args = p.parse_args()
    wp.config.quiet = True
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    data = load_dataset(args.data, robot=robot)
    cfg = SysIdConfig(fused=False if args.stepped else None)
    rng, train, dt = start_window_fit(cfg, data)
    learner = IdentifyLearner(robot, data, cfg, None, rng, train, dt, lambda *_: None, None)
    it = learner.effort_from + 1 if learner.effort_from < 10**9 else 1  # past the searches, every field fitted
    print(f"humanoid {robot.n_dof} DoF, {cfg.windows} windows, {'fused' if learner.fused else 'stepped'} replay, "
          f"fitted {', '.join(cfg.fit)}")
    print("| H | torch operators | of them kernels on CUDA | Warp launches (solver plans + wp.launch) | "
          "launches in all | per step |")
    print("|---|---|---|---|---|---|")
    found = None
    for h in args.horizons:
        learner.step(it, h, cfg.lr)  # warm-up: kernels loaded, launch plans recorded, Adam's state made
        found = count(learner, it + 1, h)
        warp = sum(found["warp"].values())
        total = found["torch_kernels"] + warp
        print(f"| {h} | {found['torch_ops']} | {found['torch_kernels']} | {warp} ({found['warp'].get('solver plan', 0)}"
              f" + {found['warp'].get('wp.launch', 0)}) | {total} | {total / h:.1f} |")
        it += 2
    if args.ops and found is not None:
        print("| operator | count | a kernel on CUDA |")
        print("|---|---|---|")
        for name, c in found["ops"].most_common():
            print(f"| {name} | {c} | {'no' if name in NO_KERNEL else 'yes'} |")


if __name__ == "__main__":
    main()
