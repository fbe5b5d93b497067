"""``wresdyn identify`` against ``mujoco.sysid``, side by side on one dataset, back to back on the same cores.

Both identify the same parameter set (per joint kp, kd, armature, damping, friction, effort limit, delay; per
moving link mass, centre of mass, inertia) from the same training trajectories, starting from the robot file's
values; ``mujoco.sysid`` runs through :mod:`peer_adapter` (its choices are stated there) with a wall-clock budget.
Each tool is scored the way the project scores a model: open-loop replay of every whole validation / held-out /
OOD trajectory from its first recorded state, mean |Δq| over the fitted joints
(:func:`wresdyn.evaluation.open_loop.metrics`), each model in its own simulator (wresdyn's in SolverReplay, the
peer's in MuJoCo); parameters against the truth of the simulated real robot with the project's identification
table (:func:`wresdyn.evaluation.identification.identification_table`).

Wall-clock: each tool's time from its start (wresdyn: kernel warm-up, setup and training; the peer: spec,
parameters, sequences and optimisation), validation replays excluded for both (wresdyn's curve excludes its own;
the peer's candidates are validated afterwards). The curve is the best validation error so far against that time:
wresdyn validates every ``select_every`` iterations, the peer every Gauss-Newton candidate that lowered its cost.

    python benchmarks/peer_sysid.py data/dataset.npz --out benchmarks/results/peer_sysid/default

A budgeted, single-call comparison (the peer at the recording step on a few windows); the peer run its own way
(every training sample, the real robot's step, staged, to its own termination, resumable) is
``benchmarks/peers/humanoid.py``, whose scoring and ``wresdyn identify`` runner this script shares.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path[:0] = [str(Path(__file__).resolve().parents[1]), str(Path(__file__).resolve().parent),
                str(Path(__file__).resolve().parent / "peers")]  # this checkout, benchmarks/ and the fights
import peer_adapter as peer  # noqa: E402
from humanoid import SPLITS, best_so_far, identify_wresdyn, param_errors, time_to  # noqa: E402


def load_avg() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def run_wresdyn(robot, ds, out: Path, iterations: int | None, log) -> dict:
    w = identify_wresdyn(robot, ds, out, "cpu", log, iterations)
    return w | {"final": w["scores"], "load_start": f"{w['load_start']:.2f}", "load_end": f"{w['load_end']:.2f}"}


def run_peer(robot, ds, args, log) -> dict:
    from wresdyn.evaluation.open_loop import metrics

    load0 = load_avg()
    run = peer.identify_peer(robot, ds.split("train"), ds.rate_hz, horizon=args.peer_horizon or None,
                             chunks=args.peer_chunks, max_iters=args.peer_max_iters, budget_s=args.peer_budget,
                             threads=args.threads, log=log)
    load1 = load_avg()
    weights, val = ds.fit_weights(), ds.split("validation")
    points, best_cost, scored = [], np.inf, []
    for t, x, cost in run.evaluations:  # validated afterwards: the candidates that lowered the cost
        if cost < best_cost:
            best_cost = cost
            v = metrics(val, peer.replay(run.model(x), val, args.threads), weights).mean_abs_dq
            points.append((t, v))
            scored.append((v, x, cost))
    v_sel, x_sel, _ = min(scored, key=lambda s: s[0])  # selection on validation, as wresdyn's
    model = run.model(x_sel)
    final = {split: metrics(ds.split(split), peer.replay(model, ds.split(split), args.threads), weights).mean_abs_dq
             for split in SPLITS}
    x_min = run.best()[1]  # what optimize() itself returns: the lowest training cost
    m_min = run.model(x_min)
    final_min = {split: metrics(ds.split(split), peer.replay(m_min, ds.split(split), args.threads),
                                weights).mean_abs_dq for split in SPLITS}
    return {"params": peer.physical_params(model, robot), "curve": best_so_far(points), "final": final,
            "final_min_cost": final_min, "total_s": run.evaluations[-1][0], "iterations": run.iterations,
            "stopped": run.stopped, "n_params": run.params.size, "load_start": load0, "load_end": load1}


def truth_in_peer(robot, ds, truth, threads: int = 2) -> dict:
    """Whole-trajectory errors of the real robot's true parameters in the peer's model (MuJoCo at the recording
    step): the floor of what the peer can reach."""
    from wresdyn.evaluation.open_loop import metrics

    model = peer.with_params(peer.peer_spec(robot, ds.rate_hz), truth)
    return {s: metrics(ds.split(s), peer.replay(model, ds.split(s), threads), ds.fit_weights()).mean_abs_dq
            for s in SPLITS}


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data", help="dataset recorded on the simulated real robot (.npz)")
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--threads", type=int, default=2, help="MuJoCo rollout threads of the peer (default 2)")
    p.add_argument("--peer-budget", type=float, default=480.0, help="peer wall-clock budget [s] (default 480)")
    p.add_argument("--peer-horizon", type=int, default=200,
                   help="peer sequence length [samples]; 0: whole trajectories (default 200)")
    p.add_argument("--peer-chunks", type=int, default=1, help="peer sequences per training trajectory (default 1)")
    p.add_argument("--peer-max-iters", type=int, default=100, help="peer Gauss-Newton iterations at most")
    p.add_argument("--iterations", type=int, default=None, help="wresdyn iterations (default: its default)")
    args = p.parse_args()

    from absl import logging as absl_logging

    from wresdyn.data.loading import load_data
    from wresdyn.data.real_robot import Mismatch, RealRobot

    absl_logging.set_verbosity(absl_logging.ERROR)  # the peer warns once per sequence that it has no sensors
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    logf = (out / "log.txt").open("w")

    def log(line: str) -> None:
        print(line, flush=True)
        logf.write(line + "\n")
        logf.flush()

    ds, robot = load_data(args.data, None, None)
    truth = RealRobot(robot, Mismatch.from_dict(ds.mismatch), ds.rate_hz).physics()
    log(f"# {args.data}: {len(ds.split('train'))} training trajectories; {os.cpu_count()} CPUs visible, "
        f"load average {load_avg()}; command: python benchmarks/{Path(__file__).name} {' '.join(sys.argv[1:])}")
    w = run_wresdyn(robot, ds, out / "wresdyn", args.iterations, log)
    log(f"# wresdyn done in {w['total_s']:.0f}s (load {w['load_start']} -> {w['load_end']})")
    pr = run_peer(robot, ds, args, log)
    log(f"# peer done in {pr['total_s']:.0f}s, {pr['iterations']} iterations, stopped: {pr['stopped']} "
        f"(load {pr['load_start']} -> {pr['load_end']})")
    train = ds.split("train")
    errs = {"wresdyn": param_errors(w["params"], truth, train), "peer": param_errors(pr["params"], truth, train)}
    peer_best = pr["curve"][-1][1]
    t_peer = time_to(pr["curve"], peer_best)
    t_w = time_to(w["curve"], peer_best)
    summary = {
        "data": args.data, "args": vars(args),
        "wresdyn": {k: w[k] for k in ("curve", "final", "setup_s", "total_s", "train_s", "load_start", "load_end")},
        "peer": {k: pr[k] for k in ("curve", "final", "final_min_cost", "total_s", "iterations", "stopped",
                                    "n_params", "load_start", "load_end")},
        "param_errors": errs, "peer_best_validation": peer_best, "peer_time_to_best_s": t_peer,
        "wresdyn_time_to_peer_best_s": t_w,
        "ratio_to_peer_wall": (t_w / pr["total_s"]) if t_w is not None else None,
        "truth_in_peer_model": truth_in_peer(robot, ds, truth, args.threads),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=1))
    w["params"].save(out / "wresdyn_physics.json")
    pr["params"].save(out / "peer_physics.json")
    log("")
    log("| mean \\|Δq\\| [rad] | wresdyn identify | mujoco.sysid |")
    log("|---|---|---|")
    for split in SPLITS:
        log(f"| {split} | {w['final'][split]:.4f} | {pr['final'][split]:.4f} |")
    log(f"| wall-clock [s] | {w['total_s']:.0f} | {pr['total_s']:.0f} ({pr['iterations']} it., {pr['stopped']}) |")
    log(f"| time to the peer's best validation {peer_best:.4f} rad [s] | "
        f"{t_w if t_w is None else round(t_w, 1)} | {round(t_peer, 1)} |")
    log(f"| the truth in the peer's model class, val / held-out / OOD | | "
        + " / ".join(f"{summary['truth_in_peer_model'][s]:.4f}" for s in SPLITS) + " |")
    for f in ("within_10pct", "median_err_kp", "median_err_kd", "median_err_armature", "median_err_damping",
              "median_err_friction", "median_err_effort", "median_err_delay", "median_err_mass", "median_err_com_m"):
        a, b = errs["wresdyn"][f], errs["peer"][f]
        fmt = (lambda v: f"{v} / {errs['wresdyn']['identifiable']}") if f == "within_10pct" else "{:.3f}".format
        log(f"| {f} | {fmt(a)} | {fmt(b)} |")
    log(f"| peer's own return (lowest training cost) val / held-out / OOD | | "
        + " / ".join(f"{pr['final_min_cost'][s]:.4f}" for s in SPLITS) + " |")
    log("")
    log("levels (best validation so far [rad]: wresdyn s, peer s):")
    levels = sorted({round(v, 4) for _, v in pr["curve"]} | {round(v, 4) for _, v in w["curve"]}, reverse=True)
    for lv in levels:
        log(f"  {lv:.4f}: {time_to(w['curve'], lv)}  {time_to(pr['curve'], lv)}")
    log(f"# load average at the end {load_avg()}")


if __name__ == "__main__":
    main()
