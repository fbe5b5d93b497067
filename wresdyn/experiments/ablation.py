"""The PPO-vs-gradient ablation: learner × network × residual kind × seeds, evaluated identically.

Every cell trains in ``segments`` equal chunks through the learner's own checkpoint/resume path, and after each
chunk the current residual is evaluated open loop on the validation split
(:func:`wresdyn.evaluation.open_loop.evaluate_split`, the same code for every learner). That gives learning curves of
validation error against training wall-clock (evaluation time excluded) and against simulated env-steps; held-out
and OOD are evaluated once, at the end, for the table. The whole ablation is resumable: a finished cell keeps its
``result.json`` and is skipped when the command runs again.

Learners: ``ppo`` (rsl-rl, Table I rewards), ``gradient`` (backprop through the simulation, same networks) and
``parametric`` (the gradient machinery fitting per-joint gains, damping, friction and armature; torque only, no
network, so it has one cell per seed).
"""

from __future__ import annotations

import dataclasses
import json
import time
from pathlib import Path

import numpy as np

from ..config_fields import set_field, set_fields
from ..errors import WresdynError
from ..evaluation.open_loop import evaluate_split
from ..evaluation.plots import save_figure
from ..fit.gradfit import fit
from ..fit.gradfit_config import GradFitConfig
from ..learn.run_residual import load_policy
from ..ppo.ppo_config import default_config
from ..ppo.trainer import train
from .ablation_config import AblationConfig

__all__ = ["AblationConfig", "cells", "run_cell", "run_cells", "run_ablation", "write_summary", "table_markdown",
           "plot_curves"]


def cells(cfg: AblationConfig) -> list[dict]:
    """The cells to run, each ``{"learner", "arch", "kind", "seed", "name"}``."""
    out = []
    for learner in cfg.learners:
        archs = ("-",) if learner == "parametric" else cfg.archs
        kinds = ("torque",) if learner == "parametric" else cfg.kinds
        for arch in archs:
            for kind in kinds:
                for seed in cfg.seeds:
                    name = f"{learner}-{arch}-{kind}-s{seed}" if learner != "parametric" else f"parametric-s{seed}"
                    out.append({"learner": learner, "arch": arch, "kind": kind, "seed": seed, "name": name})
    return out


def _evaluate(robot, dataset, policy, kind, cfg: AblationConfig, split: str) -> dict:
    summary, _ = evaluate_split(robot, dataset.split(split), dataset.rate_hz, policy, kind=kind, solver=cfg.solver,
                                device=cfg.device, weights=dataset.fit_weights())
    return summary


def _ppo_segments(cell, robot, dataset, cfg: AblationConfig, out: Path):
    cell_fields = {"residual.arch": cell["arch"], "residual.kind": cell["kind"], "ppo.seed": cell["seed"],
                   "ppo.device": cfg.device, "env.solver": cfg.solver,
                   "ppo.save_interval": max(1, cfg.ppo_iterations // cfg.segments)}
    tc = set_fields(default_config(), {**cfg.ppo_overrides, **cell_fields})
    for s in range(1, cfg.segments + 1):
        its = cfg.ppo_iterations * s // cfg.segments
        summary = train(dataset, robot, set_field(tc, "ppo.iterations", its), out, resume=True)
        policy, _ = load_policy(out)
        yield its, summary["wall_s_this_session"], summary["env_steps_this_session"], policy


def _gradient_segments(cell, robot, dataset, cfg: AblationConfig, out: Path):
    residual = dataclasses.replace(GradFitConfig().residual, kind=cell["kind"],
                                   arch=cell["arch"] if cell["arch"] != "-" else "mlp")
    gc = GradFitConfig(residual=residual,
                       model="parametric" if cell["learner"] == "parametric" else "network",
                       seed=cell["seed"], solver=cfg.solver, device=cfg.device)
    # one schedule (curriculum, learning rate) over all segments: each segment stops at `until` and resumes
    gc = dataclasses.replace(gc, iterations=cfg.gradient_iterations, **cfg.gradient_overrides)
    done_wall, done_steps = 0.0, 0
    for s in range(1, cfg.segments + 1):
        its = cfg.gradient_iterations * s // cfg.segments
        policy, curve = fit(robot, dataset, gc, out=out, log=lambda *_: None, until=its)
        wall, steps = curve[-1]["wall"], curve[-1]["sim_steps"]
        yield its, wall - done_wall, steps - done_steps, policy
        done_wall, done_steps = wall, steps


def run_cell(cell: dict, robot, dataset, cfg: AblationConfig, out: str | Path, log=print) -> dict:
    """Train one cell in segments, evaluate after each, write and return ``result.json``."""
    out = Path(out)
    result_path = out / "result.json"
    if result_path.is_file():
        return json.loads(result_path.read_text())
    out.mkdir(parents=True, exist_ok=True)
    segments = _ppo_segments if cell["learner"] == "ppo" else _gradient_segments
    curve, wall, steps = [], 0.0, 0
    policy = None
    # learning curves on validation (what choices are made on); held-out and OOD once, at the end, for reporting
    curve_split = "validation" if dataset.split("validation") else "heldout"
    for its, seg_wall, seg_steps, policy in segments(cell, robot, dataset, cfg, out):
        wall, steps = wall + seg_wall, steps + seg_steps
        val = _evaluate(robot, dataset, policy, cell["kind"], cfg, curve_split)
        curve.append({"iteration": its, "wall_s": wall, "sim_steps": steps, "split": curve_split,
                      "error": val["pd_residual"]["mean_abs_dq"], "pd_only": val["pd_only"]["mean_abs_dq"]})
        log(f"  {cell['name']}: iteration {its}, {wall:.0f} s, {steps:.2e} steps, {curve_split} "
            f"{curve[-1]['error']:.4f} rad")
    held = _evaluate(robot, dataset, policy, cell["kind"], cfg, "heldout")
    ood = _evaluate(robot, dataset, policy, cell["kind"], cfg, "ood")
    result = {**cell, "curve": curve, "wall_s": wall, "sim_steps": steps,
              "heldout": held["pd_residual"], "heldout_pd_only": held["pd_only"],
              "ood": ood["pd_residual"], "ood_pd_only": ood["pd_only"]}
    tmp = result_path.with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1))
    tmp.replace(result_path)
    return result


def _worker_init() -> None:
    import torch

    torch.set_num_threads(1)  # one core per cell: the cells themselves are the parallelism


def _run_task(task) -> dict:
    cell, robot, dataset, cfg, out = task
    return run_cell(cell, robot, dataset, cfg, out, log=lambda msg: print(msg, flush=True))


def cell_devices(device: str, n: int, gpus: int | None = None) -> list[str]:
    """The device of each of ``n`` cells: ``cuda`` (no index) spreads them round-robin over the host's ``gpus``
    GPUs (default: all torch sees), ``cuda:i`` and ``cpu`` are every cell's."""
    if device != "cuda":
        return [device] * n
    if gpus is None:
        import torch

        gpus = torch.cuda.device_count()
    if gpus < 1:
        raise WresdynError("ablation device 'cuda' spreads cells over the host's GPUs, and torch sees none here")
    return [f"cuda:{i % gpus}" for i in range(n)]


def run_cells(tasks: list[tuple], jobs: int = 1, log=print) -> list[dict]:
    """Run (or resume) cells, each task ``(cell, robot, dataset, cfg, out_dir)``; results in task order.

    With ``jobs`` > 1 the cells run in that many worker processes (spawned, one torch thread each; the robot
    and dataset travel by pickle, the robot as its :func:`~wresdyn.robot.description.load_robot` call). Each cell times
    its own training only; cells that share a machine's memory and caches run slower than on an idle core.
    A ``cfg.device`` of ``cuda`` places the cells round-robin on the host's GPUs (:func:`cell_devices`): with
    ``jobs`` a multiple of the GPU count, each GPU trains ``jobs / GPUs`` cells at a time.
    """
    if any(t[3].device == "cuda" for t in tasks):
        devices = cell_devices("cuda", len(tasks))
        tasks = [(c, r, d, dataclasses.replace(cfg, device=dev) if cfg.device == "cuda" else cfg, o)
                 for (c, r, d, cfg, o), dev in zip(tasks, devices)]
    if jobs <= 1:
        out = []
        for i, task in enumerate(tasks, 1):
            log(f"[{i}/{len(tasks)}] {task[0]['name']}")
            out.append(run_cell(*task, log=log))
        return out
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    results: list[dict | None] = [None] * len(tasks)
    with ProcessPoolExecutor(jobs, mp_context=mp.get_context("spawn"), initializer=_worker_init) as pool:
        futures = {pool.submit(_run_task, task): i for i, task in enumerate(tasks)}
        for n, fut in enumerate(as_completed(futures), 1):
            i = futures[fut]
            results[i] = fut.result()
            log(f"[{n}/{len(tasks)}] {tasks[i][0]['name']} done: held-out {results[i]['heldout']['mean_abs_dq']:.4f} rad")
    return results  # type: ignore[return-value]


def write_summary(results: list[dict], cfg: AblationConfig, out: str | Path) -> None:
    """Write ``results.json``, ``table.md`` and ``curves.png`` for finished cells into ``out``."""
    out = Path(out)
    (out / "results.json").write_text(json.dumps(results, indent=1))
    (out / "table.md").write_text(table_markdown(results, cfg))
    plot_curves(results, out / "curves.png")


def run_ablation(robot, dataset, cfg: AblationConfig, out: str | Path, log=print, jobs: int = 1) -> list[dict]:
    """Run (or resume) every cell, ``jobs`` at a time; write ``table.md``, ``results.json`` and ``curves.png``."""
    out = Path(out)
    t0 = time.perf_counter()
    results = run_cells([(c, robot, dataset, cfg, out / c["name"]) for c in cells(cfg)], jobs, log)
    write_summary(results, cfg, out)
    log(f"ablation done in {time.perf_counter() - t0:.0f} s: {out / 'table.md'}")
    return results


def _ms(values) -> str:
    v = np.asarray(values, dtype=np.float64)
    return f"{v.mean():.4f} ± {v.std():.4f}" if len(v) > 1 else f"{v.mean():.4f}"


def table_markdown(results: list[dict], cfg: AblationConfig) -> str:
    """Mean ± std over seeds per (learner, network, kind): held-out and OOD mean |Δq|, wall-clock, sim steps."""
    groups: dict[tuple, list[dict]] = {}
    for r in results:
        groups.setdefault((r["learner"], r["arch"], r["kind"]), []).append(r)
    pd_h = results[0]["heldout_pd_only"]["mean_abs_dq"] if results else float("nan")
    pd_o = results[0]["ood_pd_only"]["mean_abs_dq"] if results else float("nan")
    lines = [
        f"PD-only: held-out {pd_h:.4f} rad, OOD {pd_o:.4f} rad (mean |Δq|, open loop over whole trajectories).",
        "",
        "| learner | network | residual | seeds | held-out mean abs dq [rad] | x vs PD | OOD mean abs dq [rad] | wall-clock [s] | sim steps |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for (learner, arch, kind), rs in groups.items():
        held = [r["heldout"]["mean_abs_dq"] for r in rs]
        lines.append(f"| {learner} | {arch} | {kind} | {len(rs)} | {_ms(held)} | {pd_h / np.mean(held):.1f}x | "
                     f"{_ms([r['ood']['mean_abs_dq'] for r in rs])} | {np.mean([r['wall_s'] for r in rs]):.0f} | "
                     f"{np.mean([r['sim_steps'] for r in rs]):.2e} |")
    lines += ["", f"Solver {cfg.solver}, device {cfg.device}; PPO {cfg.ppo_iterations} iterations, gradient "
              f"{cfg.gradient_iterations} iterations per cell; wall-clock excludes evaluation."]
    return "\n".join(lines) + "\n"


def plot_curves(results: list[dict], path: str | Path) -> Path:
    """Validation error against wall-clock and against simulated steps, one line per (learner, network, kind)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
    groups: dict[str, list[dict]] = {}
    for r in results:
        groups.setdefault(f"{r['learner']} {r['arch']} {r['kind']}".replace(" - ", " "), []).append(r)
    for label, rs in groups.items():
        n = min(len(r["curve"]) for r in rs)
        err = np.mean([[p["error"] for p in r["curve"][:n]] for r in rs], axis=0)
        wall = np.mean([[p["wall_s"] for p in r["curve"][:n]] for r in rs], axis=0)
        steps = np.mean([[p["sim_steps"] for p in r["curve"][:n]] for r in rs], axis=0)
        style = "-" if rs[0]["learner"] == "ppo" else ("--" if rs[0]["learner"] == "gradient" else ":")
        axes[0].plot(wall, err, style, marker="o", label=label)
        axes[1].plot(steps, err, style, marker="o", label=label)
    split = results[0]["curve"][0]["split"] if results and results[0]["curve"] else "validation"
    if results and results[0]["curve"]:
        for ax in axes:
            ax.axhline(results[0]["curve"][0]["pd_only"], color="gray", lw=1, label="PD only")
    axes[0].set_xlabel("training wall-clock [s]")
    axes[1].set_xlabel("simulated env-steps")
    axes[1].set_xscale("log")
    axes[0].set_ylabel(f"{split} mean |Δq| [rad]")
    axes[1].legend(fontsize=7)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)
