"""Where one identification iteration's time goes (``wresdyn identify``'s default configuration): the iteration
timed whole, then by part with the device synchronised around each, and its kernels and host synchronisations
counted under ``torch.profiler``.

    python benchmarks/speed/profile_identify.py --device cuda:0           # step by step (SysIdConfig.fused=False)
    python benchmarks/speed/profile_identify.py --device cpu              # the same parts on the CPU
    python benchmarks/speed/profile_identify.py --device cuda:0 --fused   # each batch in one launch (the default's choice
                                                                    # for the humanoid)

Workload: the shipped benchmark (``data/dataset.npz``, the project humanoid, 21 DoF), :class:`SysIdConfig`'s
defaults (32 windows; ``--horizon`` steps, default 64, the curriculum's mean length), built as
:func:`wresdyn.identify.sysid.identify` builds it (the same ``IdentifyLearner``, its iterations after the effort
limit has joined the fit). The parts: the physical parameters from their coordinates and into the simulator's
arrays, the rollout (forward through every step, recording its tape), the loss, the backward pass (every step's
adjoint), and clipping, Adam and the projection. What the parts' sum leaves of the whole iteration is the
synchronisations' cost. On a GPU, kernel GPU time against the wall-clock shows whether the iteration is bound by
work or by launches and Python.
"""

from __future__ import annotations

import argparse
import json
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.identify.sysid import SysIdConfig, IdentifyLearner
    from wresdyn.learn.window_fit import squared_error, start_window_fit
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim import rollout
    from wresdyn.sim.fused import fused_rollout

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--horizon", type=int, default=64)
    p.add_argument("--repeat", type=int, default=10, help="iterations timed")
    p.add_argument("--fused", action="store_true", help="SysIdConfig.fused: the windows replayed in one launch")
    p.add_argument("--sim-threads", type=int, default=1, help="SysIdConfig.sim_threads: the solver's CPU host threads")
    p.add_argument("--json", default=None)
    args = p.parse_args()
    wp.config.quiet = True
    robot = load_robot(DEFAULT_ROBOT)
    dataset = load_dataset(args.data, robot=robot)
    cfg = SysIdConfig(device=args.device, torch_threads=1, fused=args.fused, sim_threads=args.sim_threads)
    rng, train, dt = start_window_fit(cfg, dataset)
    learner = IdentifyLearner(robot, dataset, cfg, None, rng, train, dt, lambda s: None, None)
    cuda = learner.sim.device.type == "cuda"
    h, it0 = args.horizon, learner.effort_from + 1  # past the grid searches, the effort limit in the fit

    def sync():
        if cuda:
            torch.cuda.synchronize(learner.sim.device)

    def step(k):
        learner.step(it0 + k, h, cfg.lr)

    for k in range(3):  # compile and warm up
        step(k)
    sync()
    t = time.perf_counter()
    for k in range(args.repeat):
        step(k)
    sync()
    whole = (time.perf_counter() - t) / args.repeat

    # the same iteration by part, each part synchronised (the learner's step, spelled out)
    model, sim = learner.model, learner.sim
    parts = defaultdict(float)

    def timed(name, fn):
        sync()
        t = time.perf_counter()
        out = fn()
        sync()
        parts[name] += time.perf_counter() - t
        return out

    for _ in range(args.repeat):
        learner.bank.set_delay(model.delay_steps().float().to(sim.device))
        window = timed("draw the windows", lambda: learner.bank.sample(rng, cfg.windows, h))
        timed("parameters into the simulator", lambda: sim.set_physics(model()))
        q, qd = timed("rollout (forward, tape)", lambda: fused_rollout(sim, window) if cfg.fused else
                      (lambda r: (r.q, r.qd))(rollout(sim, window, grad=True)))
        loss = timed("loss", lambda: cfg.w_q * squared_error(q[:, 1:], window.q[:, 1:], learner.weights)
                     + cfg.w_qd * squared_error(qd[:, 1:], window.qd[:, 1:], learner.weights)
                     + cfg.w_prior * model.prior().to(sim.device))
        learner.optim.zero_grad()
        timed("backward (adjoint)", lambda: loss.backward())

        def update():
            torch.nn.utils.clip_grad_norm_(model.parameters(), cfg.grad_clip)
            learner.optim.step()
            model.project()

        timed("clip, Adam, projection", update)
    parts = {k: v / args.repeat for k, v in parts.items()}

    kernels = syncs = None
    if cuda:
        acts = [torch.profiler.ProfilerActivity.CPU, torch.profiler.ProfilerActivity.CUDA]
        with torch.profiler.profile(activities=acts) as prof:
            step(args.repeat)
            sync()
        count, busy, syncs = 0, 0.0, defaultdict(int)
        for e in prof.events():
            if e.device_type == torch.autograd.DeviceType.CUDA:
                count += 1
                busy += e.device_time * 1e-6  # us -> s
            elif e.name in ("cudaStreamSynchronize", "cudaDeviceSynchronize", "cudaMemcpy", "cudaEventSynchronize"):
                syncs[e.name] += 1
        kernels = {"count": count, "gpu_ms": 1e3 * busy}
    name = torch.cuda.get_device_name(sim.device) if cuda else "CPU"
    print(f"{name} ({args.device}); {'fused' if cfg.fused else 'stepped'} replay; humanoid {robot.n_dof} DoF; "
          f"{cfg.windows} windows x {h} steps, "
          f"{args.repeat} iterations per figure")
    print(f"iteration: {1e3 * whole:.1f} ms")
    print("| part (synchronised) | ms / iteration | share of the parts |")
    print("|---|---|---|")
    total = sum(parts.values())
    for k, v in parts.items():
        print(f"| {k} | {1e3 * v:.2f} | {100 * v / total:.0f} % |")
    print(f"| sum of the parts | {1e3 * total:.2f} | |")
    if kernels is not None:
        print(f"kernels of one iteration: {kernels['count']} ({kernels['count'] / h:.1f} per step), GPU busy "
              f"{kernels['gpu_ms']:.2f} ms = {100 * kernels['gpu_ms'] / (1e3 * whole):.0f} % of the iteration; "
              f"host synchronisations: {dict(syncs) or 'none seen'}")
    if args.json:
        Path(args.json).write_text(json.dumps({"device": name, "fused": cfg.fused, "windows": cfg.windows, "horizon": h,
                                               "iteration_ms": 1e3 * whole,
                                               "parts_ms": {k: 1e3 * v for k, v in parts.items()},
                                               "kernels": kernels, "syncs": syncs}, indent=1))


if __name__ == "__main__":
    main()
