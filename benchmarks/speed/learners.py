"""Throughput of the two learners on one device: PPO (env-steps/s, s per iteration) and the gradient fit.

    python benchmarks/speed/learners.py                                    # CPU: 256 PPO envs, 32 windows
    python benchmarks/speed/learners.py --device cuda:0 --envs 256,1024,4096,16384 --windows 32,256,1024,4096

Workload: the shipped benchmark (``data/dataset.npz``, the project humanoid, 21 DoF, dt = 2 ms).

- PPO: :func:`wresdyn.ppo.trainer.train` with the default config (24 steps per env per iteration, MLP 256-128-64,
  5 epochs x 4 mini-batches) and ``--envs`` worlds, ``--ppo-iterations`` iterations after a 2-iteration
  warm-up run. ``collect`` = the rollout (policy + :class:`ReplayEnv.step`), ``learn`` = the PPO update, as rsl-rl
  times them; env-steps/s (collection) = env-steps / collection time. Peers: every ``--solvers`` entry and, on
  CUDA, ``--graphs on,off`` (environment step replayed from a CUDA graph, or eager) in the same run.
- Gradient fit: :func:`wresdyn.fit.gradfit.fit` with ``--windows`` parallel windows of ``--horizon`` steps (no
  curriculum), ``--grad-iterations`` iterations after 2 warm-up ones (the eager one and the capture, on CUDA). One
  env-step = one window advanced one step, forward and backward counted once each (as in ``curve.json``'s
  ``sim_steps``). On CUDA ``--graphs`` applies here too (the whole iteration replayed from a CUDA graph, or eager).

Prints a table and writes JSON (``--json``). The learners run as they do in training.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import platform
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _ppo(robot, dataset, device: str, envs: int, iterations: int, solver: str, graph: bool = True) -> dict:
    from wresdyn.ppo.trainer import train
    from wresdyn.ppo.ppo_config import default_config

    cfg = default_config()
    cfg = dataclasses.replace(cfg, env=dataclasses.replace(cfg.env, solver=solver, num_worlds=envs),
                              ppo=dataclasses.replace(cfg.ppo, device=device, save_interval=10**6,
                                                      select_every=10**6, cuda_graph=graph))
    with tempfile.TemporaryDirectory() as tmp:
        train(dataset, robot, dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, iterations=2)), Path(tmp) / "warm")
        s = train(dataset, robot, dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, iterations=iterations)),
                  Path(tmp) / "run")
    return {"learner": "ppo" + (" graph" if s["cuda_graph"] else ""), "device": device, "solver": s["solver"],
            "size": envs, "iterations": iterations, "s_per_iteration": s["s_per_iteration"],
            "collect_s": s["collect_s_per_iteration"], "learn_s": s["learn_s_per_iteration"],
            "env_steps_per_s": s["collection_steps_per_s"], "training_steps_per_s": s["training_steps_per_s"]}


def _gradient(robot, dataset, device: str, windows: int, horizon: int, iterations: int, graph: bool = True) -> dict:
    from wresdyn.fit.gradfit import GradFitConfig, fit

    cfg = GradFitConfig(windows=windows, horizon=horizon, horizon_curriculum=(), iterations=iterations + 2,
                        device=device, select_every=10**6, cuda_graph=graph)  # validation once, at the end
    _, curve = fit(robot, dataset, cfg, log=lambda *_: None)  # rows 1, 2 and the last wait for the device
    a, b = curve[1], curve[-1]  # exclude the first two iterations (compilation, allocation, the graph's capture)
    wall, steps = b["wall"] - a["wall"], b["sim_steps"] - a["sim_steps"]
    graphed = graph and device.startswith("cuda")
    return {"learner": "gradient" + (" graph" if graphed else ""), "device": device, "solver": "SolverReplay",
            "size": windows, "horizon": horizon,
            "iterations": iterations, "s_per_iteration": wall / iterations, "env_steps_per_s": steps / wall,
            "training_steps_per_s": steps / wall}


def main() -> None:
    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--envs", default="256", help="comma list of PPO env counts")
    p.add_argument("--solvers", default="auto", help="comma list of PPO solvers (auto, featherstone, mujoco)")
    p.add_argument("--graphs", default="on", help="CUDA: PPO environment step and gradient-fit iteration from CUDA graphs: "
                   "on, off or on,off")
    p.add_argument("--ppo-iterations", type=int, default=10)
    p.add_argument("--windows", default="32", help="comma list of gradient-fit window counts")
    p.add_argument("--horizon", type=int, default=64, help="gradient-fit window length [steps]")
    p.add_argument("--grad-iterations", type=int, default=10)
    p.add_argument("--json", default=None, help="write the rows here")
    args = p.parse_args()
    wp.config.quiet = True
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    dataset = load_dataset(args.data, robot=robot)
    rows = []
    graphs = [g == "on" for g in args.graphs.split(",")] if args.device.startswith("cuda") else [False]
    for solver in args.solvers.split(","):
        for graph in graphs:
            for envs in (int(x) for x in args.envs.split(",") if x):
                t = time.perf_counter()
                try:
                    rows.append(_ppo(robot, dataset, args.device, envs, args.ppo_iterations, solver, graph))
                except Exception as e:  # a failing configuration is reported, the others still run
                    print(f"ppo {solver} graph={graph} {envs}: FAILED {type(e).__name__}: {str(e)[:300]}", flush=True)
                    continue
                print(f"ppo {solver} graph={graph} {envs}: {time.perf_counter() - t:.0f} s", flush=True)
    for graph in graphs:
        for w in (int(x) for x in args.windows.split(",") if x):
            rows.append(_gradient(robot, dataset, args.device, w, args.horizon, args.grad_iterations, graph))
            print(f"gradient graph={graph} {w}: done", flush=True)
    name = torch.cuda.get_device_name(args.device) if args.device.startswith("cuda") else platform.processor() or "cpu"
    print(f"\n{name}, {args.device}; humanoid 21 DoF, dt 2 ms")
    print("| learner | solver | envs / windows | s per iteration | collect / learn [s] | env-steps/s (collection) | "
          "env-steps/s (training) |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        split = f"{r['collect_s']:.3f} / {r['learn_s']:.3f}" if "collect_s" in r else "-"
        print(f"| {r['learner']} | {r['solver']} | {r['size']} | {r['s_per_iteration']:.3f} | {split} | "
              f"{r['env_steps_per_s'] / 1e3:.1f}k | {r['training_steps_per_s'] / 1e3:.1f}k |")
    if args.json:
        Path(args.json).write_text(json.dumps({"device": name, "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
