"""Time to fidelity: wall-clock for each learner to bring the validation error down to a fixed target.

    python benchmarks/speed/time_to_fidelity.py --out runs/ttf_cpu                       # CPU: 32 windows, 256 envs
    python benchmarks/speed/time_to_fidelity.py --device cuda:0 --windows 1024 --envs 4096 --out runs/ttf_gpu

Workload: the shipped benchmark (``data/dataset.npz``, the project humanoid, 21 DoF, dt = 2 ms). Target: the
validation error (open-loop replay of the validation split from the first recorded state, the metric every learner
is selected by) at or below the PD-only validation error divided by ``--ratio`` (default 3). Each learner trains
with its defaults at the given size, checks validation every ``--check`` iterations and stops at the first check at
or below the target (``stop_below`` of :func:`wresdyn.ppo.trainer.train` and :func:`wresdyn.fit.gradfit.fit`):

- ``gradient``: the gradient fit (network residual, MLP, its default 2000-iteration schedule) with ``--windows``;
  on CUDA each iteration is replayed from a CUDA graph (``--no-graph``: also eager, the peer);
- ``ppo``: PPO (rsl-rl, default configuration) with ``--envs`` worlds, at most ``--ppo-iterations``; on CUDA the
  environment step is replayed from a CUDA graph (``--no-graph``: also eager, the peer).

Reported per learner: training wall-clock to the target (validation checks excluded), the process wall-clock
including start-up and checks, the gradient fit's training wall-clock of the whole run (``train_s``), iterations,
env-steps and env-steps/s, the mean GPU utilisation sampled through NVML while it trained (CUDA), and the held-out
error of the returned residual, for reference only (nothing is chosen on it). A learner that misses the target within its iterations is reported as such, with its best validation error.
Prints a table; ``--out`` gets ``results.json`` and the run folders.
"""

from __future__ import annotations

import argparse
import json
import platform
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


class GpuSampler:
    """Mean GPU utilisation [%] of one CUDA device, sampled through NVML every ``period`` s in a thread."""

    def __init__(self, device: str, period: float = 0.2) -> None:
        self.samples: list[int] = []
        self._stop = threading.Event()
        self._handle = None
        if device.startswith("cuda"):
            try:
                import pynvml

                pynvml.nvmlInit()
                index = int(device.split(":")[1]) if ":" in device else 0
                self._handle = pynvml.nvmlDeviceGetHandleByIndex(index)
                self._nvml = pynvml
            except Exception as e:  # no NVML: the figure is left out, said so in the table
                print(f"GPU utilisation not sampled ({type(e).__name__}: {e})")
        self._thread = threading.Thread(target=self._run, args=(period,), daemon=True)

    def _run(self, period: float) -> None:
        while not self._stop.wait(period):
            self.samples.append(self._nvml.nvmlDeviceGetUtilizationRates(self._handle).gpu)

    def __enter__(self):
        if self._handle is not None:
            self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        if self._handle is not None:
            self._thread.join()

    @property
    def mean(self) -> float | None:
        return sum(self.samples) / len(self.samples) if self.samples else None


def _heldout(robot, dataset, policy, device: str) -> float:
    from wresdyn.evaluation.open_loop import evaluate_split

    summary, _ = evaluate_split(robot, dataset.split("heldout"), dataset.rate_hz, policy, device=device)
    return summary["pd_residual"]["mean_abs_dq"]


def run_gradient(robot, dataset, args, target: float, out: Path, graph: bool) -> dict:
    from wresdyn.fit.gradfit import GradFitConfig, fit

    cfg = GradFitConfig(windows=args.windows, device=args.device, select_every=args.check, seed=args.seed,
                        cuda_graph=graph)
    t = time.perf_counter()
    with GpuSampler(args.device) as gpu:
        policy, curve = fit(robot, dataset, cfg, out=out, stop_below=target)
    process = time.perf_counter() - t
    checks = [r for r in curve if "validation" in r]
    hit = next((r for r in checks if r["validation"] <= target), None)
    steps = curve[-1]["sim_steps"]
    return {"learner": "gradient" + ("" if graph or not args.device.startswith("cuda") else " (no graph)"),
            "size": args.windows, "reached": hit is not None,
            "wall_s": hit["wall"] if hit else None, "process_s": process, "train_s": curve[-1]["wall"],
            "iterations": hit["iteration"] if hit else curve[-1]["iteration"], "env_steps": steps,
            "env_steps_per_s": steps / curve[-1]["wall"], "best_validation": min(r["validation"] for r in checks),
            "gpu_util": gpu.mean, "heldout": _heldout(robot, dataset, policy, args.device)}


def run_ppo(robot, dataset, args, target: float, out: Path, graph: bool) -> dict:
    from wresdyn.learn.run_residual import load_policy
    from wresdyn.ppo.trainer import train
    from wresdyn.config_fields import set_fields
    from wresdyn.ppo.ppo_config import default_config

    cfg = set_fields(default_config(), {"env.num_worlds": args.envs, "ppo.device": args.device,
                                        "ppo.iterations": args.ppo_iterations, "ppo.select_every": args.check,
                                        "ppo.save_interval": max(args.check, 50), "ppo.seed": args.seed,
                                        "ppo.cuda_graph": graph})
    t = time.perf_counter()
    with GpuSampler(args.device) as gpu:
        s = train(dataset, robot, cfg, out, stop_below=target)
    process = time.perf_counter() - t
    curve = s["validation_curve"]
    hit = next((r for r in curve if r["validation"] <= target), None)
    policy, _ = load_policy(out)
    return {"learner": "ppo" + ("" if graph or not args.device.startswith("cuda") else " (no graph)"),
            "size": args.envs, "reached": hit is not None, "wall_s": hit["wall_s"] if hit else None,
            "process_s": process, "iterations": hit["iteration"] if hit else s["iterations_this_session"],
            "env_steps": s["env_steps_this_session"], "env_steps_per_s": s["training_steps_per_s"],
            "collect_env_steps_per_s": s.get("collection_steps_per_s"),
            "s_per_iteration": s["s_per_iteration"], "best_validation": min(r["validation"] for r in curve),
            "gpu_util": gpu.mean, "heldout": _heldout(robot, dataset, policy, args.device)}


def main() -> None:
    import torch
    import warp as wp

    from wresdyn.data.dataset import load_dataset
    from wresdyn.learn.selection import ValidationScore
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cpu")
    p.add_argument("--data", default=str(ROOT / "data" / "dataset.npz"))
    p.add_argument("--learners", default="gradient,ppo", help="comma list: gradient, ppo")
    p.add_argument("--ratio", type=float, default=3.0, help="target: PD-only validation error / RATIO")
    p.add_argument("--windows", type=int, default=32, help="gradient-fit windows")
    p.add_argument("--envs", type=int, default=256, help="PPO worlds")
    p.add_argument("--ppo-iterations", type=int, default=4000, help="PPO iterations at most")
    p.add_argument("--check", type=int, default=25, help="validation check every this many iterations")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-graph", action="store_true", help="CUDA: also run each learner eagerly (no CUDA graphs)")
    p.add_argument("--out", required=True, help="folder for results.json and the runs (resumed where present)")
    args = p.parse_args()
    wp.config.quiet = True
    torch.set_num_threads(1)
    robot = load_robot(DEFAULT_ROBOT)
    dataset = load_dataset(args.data, robot=robot)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    pd_only = ValidationScore(robot, dataset.split("validation"), dataset.rate_hz, device=args.device,
                              weights=dataset.fit_weights())()
    target = pd_only / args.ratio
    print(f"PD-only validation error {pd_only:.4f} rad; target {target:.4f} rad ({args.ratio:g}x)", flush=True)
    jobs = []
    for learner in args.learners.split(","):
        if learner == "gradient":
            jobs.append(("gradient", lambda: run_gradient(robot, dataset, args, target, out / "gradient", graph=True)))
            if args.no_graph and args.device.startswith("cuda"):
                jobs.append(("gradient (no graph)", lambda: run_gradient(robot, dataset, args, target,
                                                                         out / "gradient_nograph", graph=False)))
        elif learner == "ppo":
            jobs.append(("ppo", lambda: run_ppo(robot, dataset, args, target, out / "ppo", graph=True)))
            if args.no_graph and args.device.startswith("cuda"):
                jobs.append(("ppo (no graph)",
                             lambda: run_ppo(robot, dataset, args, target, out / "ppo_nograph", graph=False)))
        else:
            raise SystemExit(f"time_to_fidelity: unknown learner {learner!r} (gradient, ppo)")
    rows, failed = [], []
    for name, job in jobs:
        try:
            rows.append(job())
        except Exception as e:  # reported, and the other learners still run
            failed.append({"learner": name, "error": f"{type(e).__name__}: {str(e)[:300]}"})
            print(f"{name}: FAILED {failed[-1]['error']}", flush=True)
            continue
        print(json.dumps(rows[-1]), flush=True)
    name = torch.cuda.get_device_name(args.device) if args.device.startswith("cuda") else platform.processor() or "cpu"
    print(f"\n{name}, {args.device}; humanoid 21 DoF, dt 2 ms; target {target:.4f} rad = PD-only / {args.ratio:g}")
    print("| learner | envs / windows | to target [s] | training [s] | process [s] | iterations | env-steps/s | "
          "GPU util | best validation [rad] | held-out [rad] |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        reached = f"{r['wall_s']:.1f}" if r["reached"] else "not reached"
        util = f"{r['gpu_util']:.0f} %" if r["gpu_util"] is not None else "-"
        train = f"{r['train_s']:.1f}" if "train_s" in r else "-"
        print(f"| {r['learner']} | {r['size']} | {reached} | {train} | {r['process_s']:.0f} | {r['iterations']} | "
              f"{r['env_steps_per_s'] / 1e3:.0f}k | {util} | {r['best_validation']:.4f} | {r['heldout']:.4f} |")
    (out / "results.json").write_text(json.dumps({"device": name, "pd_only_validation": pd_only, "target": target,
                                                  "ratio": args.ratio, "rows": rows, "failed": failed}, indent=1))
    if failed:
        raise SystemExit(1)


if __name__ == "__main__":
    main()
