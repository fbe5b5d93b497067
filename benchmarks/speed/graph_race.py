"""Graph-replayed GPU work against the eager one while other processes load the same GPU (a stream-ordering race).

    python benchmarks/speed/graph_race.py --device cuda:0 --load 3 --repeats 5 [--only env|fit] [--json OUT.json]

The two CUDA comparisons of ``tests/learn/test_learner_speed_paths.py`` at the tests' sizes, repeated: the
replay environment's step (``ReplayEnv(graph=True)`` against ``graph=False``, 64 worlds, 6 steps: two eager warm-ups
on the simulator's stream, two captures, replays; joints excluded 0 and 3) and the gradient fit (``cuda_graph`` on
against off, 64 windows, horizons 4 then 8, 12 iterations, MLP and GRU). A missing stream ordering shows only when
the GPU is busy (an idle GPU finishes each kernel before the host queues the next), so ``--load N`` first starts N
processes of its own that keep the same GPU at full use (``--load-size`` square float32 matmuls in a loop) and stops
them at the end, whatever happened. Each step and iteration is printed with its phase (warm-up, capture, replay),
its largest difference and PASS/FAIL at the tests' tolerances (env: |Δq| <= 1e-5 rad; fit: losses within rtol 1e-3),
so a failure names the phase that raced. Exit status 1 when any repeat failed, 2 without CUDA.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import subprocess
import sys
import time

import numpy as np
import torch

from wresdyn.data.mismatch import Mismatch
from wresdyn.data.real_robot import collect
from wresdyn.fit.gradfit import GradFitConfig, fit
from wresdyn.learn.residual import ResidualConfig
from wresdyn.learn.window_fit import schedule
from wresdyn.paths import DEFAULT_MISMATCH
from wresdyn.ppo.replay_env import ReplayEnv, ReplayEnvConfig
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

COUNTS = {"train": 2, "validation": 1, "heldout": 1, "ood": 1}
"""The learner tests' recording (tests/conftest.py ``data``): 0.2 s trajectories of the shipped real robot."""
ENV_ATOL = 1e-5
"""The test's bound on graph against eager q [rad]: both run the same kernels on the same inputs."""
FIT_RTOL = 1e-3
"""The test's bound on graph against eager fit losses (relative): summation order differs in captured reductions."""
ENV_PHASES = ("warm-up", "warm-up", "capture+replay", "capture+replay", "replay", "replay")
"""What ReplayEnv(graph=True) runs at each of the 6 steps (one graph per starting state buffer, two buffers)."""


def load_worker(device: str, size: int) -> None:
    """Keep ``device`` busy until killed: back-to-back matmuls, a host sync now and then so the queue stays short."""
    torch.cuda.set_device(device)
    a = torch.randn(size, size, device=device)
    b = torch.randn(size, size, device=device)
    while True:
        for _ in range(20):
            a = torch.tanh(a @ b)
        torch.cuda.synchronize(device)


def start_load(n: int, device: str, size: int) -> list[subprocess.Popen]:
    procs = [subprocess.Popen([sys.executable, __file__, "--load-worker", "--device", device, "--load-size", str(size)])
             for _ in range(n)]
    time.sleep(5.0 if n else 0.0)  # let them allocate and reach their loops
    dead = [p.pid for p in procs if p.poll() is not None]
    if dead:
        raise RuntimeError(f"load processes {dead} exited at start")
    return procs


def stop_load(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        p.terminate()
    for p in procs:
        try:
            p.wait(timeout=20)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


def compare_env(robot, data, device: str, excluded: int) -> list[dict]:
    """The test's graph-vs-eager ReplayEnv.step, step by step: phase, max |Δq| [rad], max |Δreward|, PASS/FAIL."""
    weights = np.ones(robot.n_dof)
    weights[:excluded] = 0.0
    envs = {g: ReplayEnv(robot, data.split("train"), data.rate_hz, 64, ReplayEnvConfig(horizon=400), device=device,
                         seed=1, graph=g, weights=weights) for g in (True, False)}
    a, b = envs[True], envs[False]
    for name in ("g", "q", "qd", "qdd"):
        getattr(a, name).copy_(getattr(b, name))
    a.end.fill_(10**9)
    b.end.fill_(10**9)
    a.sim.set_state(None, b.q, b.qd)
    gen = torch.Generator(device=device).manual_seed(0)
    rows = []
    for i, phase in enumerate(ENV_PHASES):
        act = 0.5 * torch.randn(64, robot.n_dof, device=device, generator=gen)
        _, ra, _, _ = a.step(act)
        _, rb, _, _ = b.step(act)
        dq = float((a.q - b.q).abs().max())
        dr = float((ra - rb).abs().max())
        rows.append({"step": i, "phase": phase, "max_dq": dq, "max_dreward": dr, "pass": dq <= ENV_ATOL})
        a.q.copy_(b.q)  # each step judged on its own: the next starts from the eager state again
        a.qd.copy_(b.qd)
        a.qdd.copy_(b.qdd)
        a.sim.set_state(None, b.q, b.qd)
    return rows


def compare_fit(robot, data, device: str, arch: str) -> list[dict]:
    """The test's graph-vs-eager gradient fit: per iteration its window length, phase, both losses, PASS/FAIL."""
    cfg = GradFitConfig(residual=ResidualConfig(fraction=0.25, arch=arch, hidden_dims=(64, 64)), windows=64,
                        horizon_curriculum=(4, 8), iterations=12, select_every=6, device=device)
    curves = {g: fit(robot, data, dataclasses.replace(cfg, cuda_graph=g), log=lambda *_: None)[1]
              for g in (True, False)}
    rows, seen = [], {}
    for i, (ra, rb) in enumerate(zip(curves[True], curves[False])):
        h = schedule(cfg, cfg.horizon_curriculum, i)[0]  # the window length iteration i ran at
        seen[h] = seen.get(h, 0) + 1
        phase = ("warm-up", "capture+replay")[seen[h] - 1] if seen[h] <= 2 else "replay"
        rel = abs(ra["loss"] - rb["loss"]) / abs(rb["loss"])
        rows.append({"iteration": i, "horizon": h, "phase": phase, "loss_graph": ra["loss"], "loss_eager": rb["loss"],
                     "rel_diff": rel, "pass": rel <= FIT_RTOL})
    return rows


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--load", type=int, default=3, help="background GPU load processes on the same device")
    p.add_argument("--load-size", type=int, default=8192, help="matmul side of each load process")
    p.add_argument("--repeats", type=int, default=3)
    p.add_argument("--only", choices=("env", "fit"), default=None)
    p.add_argument("--json", default=None)
    p.add_argument("--load-worker", action="store_true", help=argparse.SUPPRESS)
    args = p.parse_args()
    if args.load_worker:
        load_worker(args.device, args.load_size)
        return 0
    if not (args.device.startswith("cuda") and torch.cuda.is_available()):
        print(f"graph_race.py needs CUDA: it compares CUDA-graph replays with eager GPU work (device {args.device!r}, "
              f"torch.cuda.is_available() = {torch.cuda.is_available()}); nothing run")
        return 2
    torch.set_num_threads(1)
    print(f"# {' '.join(sys.argv)}\n# {platform.node()} {torch.cuda.get_device_name(args.device)} torch "
          f"{torch.__version__}, {args.load} load processes of {args.load_size}^2 matmuls")
    robot = load_robot(DEFAULT_ROBOT)
    data = collect(robot, Mismatch.load(DEFAULT_MISMATCH), COUNTS, duration=0.2)
    results, failed = [], 0
    procs = start_load(args.load, args.device, args.load_size)
    try:
        for rep in range(args.repeats):
            if args.only in (None, "env"):
                for excluded in (0, 3):
                    rows = compare_env(robot, data, args.device, excluded)
                    ok = all(r["pass"] for r in rows)
                    failed += not ok
                    results.append({"repeat": rep, "case": f"env[{excluded}]", "pass": ok, "rows": rows})
                    print(f"repeat {rep} env[{excluded}] {'PASS' if ok else 'FAIL'}: " + "; ".join(
                        f"{r['step']} {r['phase']} max|dq| {r['max_dq']:.2e} {'ok' if r['pass'] else 'FAIL'}"
                        for r in rows), flush=True)
            if args.only in (None, "fit"):
                for arch in ("mlp", "gru"):
                    rows = compare_fit(robot, data, args.device, arch)
                    ok = all(r["pass"] for r in rows)
                    failed += not ok
                    results.append({"repeat": rep, "case": f"fit[{arch}]", "pass": ok, "rows": rows})
                    print(f"repeat {rep} fit[{arch}] {'PASS' if ok else 'FAIL'}: max rel loss diff "
                          f"{max(r['rel_diff'] for r in rows):.2e}; " + "; ".join(
                              f"{r['iteration']} h{r['horizon']} {r['phase']} {r['loss_graph']:.5f}/"
                              f"{r['loss_eager']:.5f}{'' if r['pass'] else ' FAIL'}" for r in rows), flush=True)
    finally:
        stop_load(procs)
    print(f"{len(results) - failed} of {len(results)} comparisons passed")
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"argv": sys.argv, "load": args.load, "results": results}, f, indent=1)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
