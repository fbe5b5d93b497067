"""``wresdyn demo``: the main job on the embedded defaults, end to end on a 2-core CPU in about 10 minutes.

1. robot: load ``scenes/humanoid.usda`` and check Newton against MuJoCo C on a PD replay;
2. data: the shipped dataset ``data/dataset.npz`` (made by ``wresdyn collect``; ``--collect`` records a fresh one);
3. learn: a torque residual by gradient descent through the simulation (``wresdyn fit``) and by PPO
   (``wresdyn train``), same network, same data;
4. evaluate: open-loop replay of the held-out and out-of-distribution trajectories, PD-only vs PD + residual
   (``wresdyn eval``), and a summary ``OUT/report.md`` with the Fig. 3-style plots.
"""

from __future__ import annotations

import argparse


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--out", default="runs/demo", help="output folder (default: runs/demo)")
    p.add_argument("--collect", action="store_true", help="record a fresh small dataset instead of the shipped one")
    p.add_argument("--ppo-iterations", type=int, default=1000, help="PPO iterations (0.3-0.5 s each on 2 CPU cores)")
    p.add_argument("--fit-iterations", type=int, default=2000, help="gradient-fit iterations")
    p.add_argument("--quick", action="store_true", help="tiny sizes: a smoke run of a minute")


def run(args: argparse.Namespace) -> int:
    import dataclasses
    import json
    import time
    from pathlib import Path

    from ..data.dataset import load_dataset
    from ..evaluation.runs import evaluate_run
    from ..learn.gradfit import GradFitConfig, export_run, fit
    from ..learn.ppo import default_config, train
    from ..paths import DEFAULT_DATASET, DEFAULT_MISMATCH, DEFAULT_ROBOT
    from ..robot.description import load_robot
    from ..sim.parity import pd_agreement

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    robot = load_robot(DEFAULT_ROBOT)
    a = pd_agreement(robot, 1.0, 0.002, integrator="Euler", solver="featherstone")
    print(f"[1/4] robot: {robot.source.name}, {robot.n_dof} joints, {robot.body_mass.sum():.1f} kg; Newton vs MuJoCo C "
          f"PD replay max |dq| {a.max_abs:.1e} rad", flush=True)

    data_path = DEFAULT_DATASET
    if args.collect:
        from ..data.real_robot import Mismatch, collect

        data_path = out / "data" / "dataset.npz"
        if not data_path.is_file():
            mismatch = Mismatch.load(DEFAULT_MISMATCH)
            collect(robot, mismatch, {"train": 4, "validation": 2, "heldout": 2, "ood": 2}, store_tau=False,
                    progress=lambda line: print("      " + line, flush=True)).save(data_path)
    data = load_dataset(data_path, robot=robot)
    if args.quick:
        data = dataclasses.replace(data, trajectories=data.split("train")[:2] + data.split("validation")[:1]
                                   + data.split("heldout")[:1] + data.split("ood")[:1])
    splits = ", ".join(f"{s} {len(data.split(s))}" for s in ("train", "validation", "heldout", "ood"))
    print(f"[2/4] data: {data_path} ({splits}"
          f", {data.rate_hz:g} Hz)", flush=True)

    gcfg = GradFitConfig(iterations=args.fit_iterations)
    tcfg = default_config()
    tcfg = dataclasses.replace(tcfg, ppo=dataclasses.replace(tcfg.ppo, iterations=args.ppo_iterations))
    if args.quick:
        gcfg = dataclasses.replace(gcfg, iterations=4, windows=4, horizon_curriculum=(2, 4))
        tcfg = dataclasses.replace(tcfg, ppo=dataclasses.replace(tcfg.ppo, iterations=2, num_envs=8, num_steps_per_env=8))
    print(f"[3/4] learning a torque residual: gradient fit ({gcfg.iterations} iterations) ...", flush=True)
    fit_dir = out / "gradient"
    policy, curve = fit(robot, data, gcfg, out=fit_dir, log=lambda line: print("      " + line, flush=True))
    export_run(policy, fit_dir, gcfg, data, data_path)
    print(f"      ... and PPO ({tcfg.ppo.iterations} iterations)", flush=True)
    ppo_dir = out / "ppo"
    summary = train(data, robot, tcfg, ppo_dir, resume=True)
    print("[4/4] evaluation (open loop over whole trajectories)", flush=True)
    results = {}
    for name, run_dir in (("gradient", fit_dir), ("ppo", ppo_dir)):
        print(f"      {name}:", flush=True)
        results[name] = evaluate_run(str(run_dir), data, robot, data_label=str(data_path))
    rows = ["| learner | training [s] | held-out mean abs dq [rad] | x | OOD mean abs dq [rad] | x |", "|---|---|---|---|---|---|"]
    walls = {"gradient": curve[-1]["wall"] if curve else 0.0, "ppo": summary["wall_s_this_session"]}
    for name, res in results.items():
        h, o = res.get("heldout"), res.get("ood")
        cells = [f"{r['pd_residual']['mean_abs_dq']:.4f} | {r['improvement']:.2f}x" if r else "- | -" for r in (h, o)]
        rows.append(f"| {name} | {walls[name]:.0f} | {cells[0]} | {cells[1]} |")
    pd = results["gradient"].get("heldout", {}).get("pd_only", {}).get("mean_abs_dq", float("nan"))
    report = ["# wresdyn demo", "", f"PD-only held-out mean |Δq|: {pd:.4f} rad.", "", *rows, "",
              f"Plots: `gradient/eval/fig3_heldout.png`, `ppo/eval/fig3_heldout.png`. Total {time.perf_counter() - t0:.0f} s."]
    (out / "report.md").write_text("\n".join(report) + "\n")
    (out / "results.json").write_text(json.dumps(results, indent=1))
    print("\n".join(report))
    return 0
