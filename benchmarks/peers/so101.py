"""Peers on the real SO-101: MuJoCo Playground's identification recipe, LeRobot's MuJoCo model and BAM's STS3215
model class, each fitted on the training runs of wresdyn's servo benchmark, scored on its validation, held-out and
OOD runs like the published (unfitted) models of ``benchmarks/so101_baselines.py`` and like wresdyn's servo model.

Metric: mean |Δq| [rad] over the five arm joints and every sample of whole runs, open loop from the first recorded
state (:func:`wresdyn.evaluation.servo_baselines.evaluate_baseline`, MuJoCo C, the robot file's options). The data
is the import of ``benchmarks/so101_servo_real.sh`` (same command, same splits: 26 training, 6 validation, 6
held-out, 2 OOD runs); training runs fit, validation only draws the curves, held-out and OOD are scored once per
model. The recipes and the adapter: ``so101_sysid.py`` beside this file. wresdyn's row is read from its committed
result (:data:`WRESDYN_RUN`), not rerun.

    PYTHONPATH=. python benchmarks/peers/so101.py --tarballs ../shared/real/so101 --work /tmp/peers_so101 \\
        --out benchmarks/results/peers/so101 | tee benchmarks/results/peers/so101/log.txt
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import platform
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

import mujoco
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import so101_sysid as adapter  # noqa: E402

from wresdyn.data.dataset import load_dataset  # noqa: E402
from wresdyn.evaluation.open_loop import metrics  # noqa: E402
from wresdyn.evaluation.servo_baselines import (BAM_STS3215_7V4, BamDrive, bam_model, evaluate_baseline,  # noqa: E402
                                                lerobot_model, replay)
from wresdyn.robot.description import load_robot  # noqa: E402

SPLITS = ("validation", "heldout", "ood")
WRESDYN_RUN = "benchmarks/results/so101_servo/effort/k3e4_reset"
"""wresdyn's servo model as chosen on validation (``benchmarks/so101_servo_real.sh``, seed 0): its
``eval_metrics.json`` and ``identify.log``."""
FIELDS = ("heldout_error", "ood_error", "seconds_to_final", "converged", "samples_used", "machine")


def build_dataset(tarballs: Path, work: Path, robot: str) -> Path:
    """The servo benchmark's import (``benchmarks/so101_servo_real.sh``'s ``collect`` line), built once."""
    data = work / "servo_data" / "dataset.npz"
    if data.exists():
        return data
    logs = work / "logs"
    if not (logs / "logs").is_dir():
        logs.mkdir(parents=True, exist_ok=True)
        subprocess.run(["tar", "-xJf", str(tarballs / "so101-sage-logs.tar.xz"), "-C", str(logs)], check=True)
    wresdyn = Path(sys.executable).parent / "wresdyn"
    subprocess.run([str(wresdyn), "collect", "--robot", robot, "--gains", "scenes/so101/servo.toml",
                    "--logs", str(logs / "logs"), "--map", "data/so101/map.toml", "--assign", "pick_place=ood",
                    "--assign", "figure_eight=ood", "--validation-fraction", "0.15", "--heldout-fraction", "0.15",
                    "--out", str(work / "servo_data")], check=True)
    return data


def machine() -> str:
    cpu = next((line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                if line.startswith("model name")), platform.processor())
    return f"{os.cpu_count()} CPU cores ({cpu}), shared with other jobs"


def wresdyn_row(root: Path) -> dict:
    """wresdyn's servo model from its committed files: errors from ``eval_metrics.json``, time from the
    ``done: N s`` line of ``identify.log``, windows from ``config.json``."""
    run = root / WRESDYN_RUN
    ev = json.loads((run / "eval_metrics.json").read_text())["splits"]
    cfg = json.loads((run / "config.json").read_text())["sysid"]
    log = (run / "identify.log").read_text()
    done = [line for line in log.splitlines() if line.startswith("done:")]
    seconds = float(done[-1].split()[1]) if done else None
    per_stage = cfg["iterations"] // len(cfg["horizon_curriculum"])
    samples = cfg["windows"] * per_stage * sum(cfg["horizon_curriculum"])
    return {
        "heldout_error": ev["heldout"]["pd_residual"]["mean_abs_dq"],
        "ood_error": ev["ood"]["pd_residual"]["mean_abs_dq"],
        "seconds_to_final": seconds,
        "converged": {"value": False, "reason": f"fixed budget of {cfg['iterations']} Adam iterations (no stopping "
                      "rule), the iterate chosen by validation, then the effort-limit reset"},
        "samples_used": samples,
        "machine": "2 CPU cores (AMD EPYC), shared with other jobs (identify.log's wall clock)",
        "extras": {"source": f"{WRESDYN_RUN}/eval_metrics.json, identify.log, config.json",
                   "validation_error": ev["validation"]["pd_residual"]["mean_abs_dq"],
                   "samples_used_means": "window samples stepped over the run with repeats: windows x iterations "
                                         "per horizon stage x sum of the horizons"},
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tarballs", default="../shared/real/so101", help="folder with so101-sage-logs.tar.xz")
    p.add_argument("--work", default="/tmp/peers_so101", help="scratch folder for the import")
    p.add_argument("--out", default="benchmarks/results/peers/so101")
    p.add_argument("--robot", default="scenes/so101/so101.xml")
    p.add_argument("--horizon", type=int, default=1000, help="fit window length [samples at 500 Hz]")
    p.add_argument("--per-run", type=int, default=2, help="fit windows per training run, evenly spaced")
    p.add_argument("--max-iters", type=int, default=30, help="mujoco.sysid's iteration cap")
    p.add_argument("--max-nfev", type=int, default=100, help="scipy least_squares' evaluation cap (BAM)")
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--train-runs", type=int, default=None, help="only the first N training runs (smoke tests)")
    p.add_argument("--only", default="playground,lerobot,bam", help="which fits to run")
    p.add_argument("--no-unfitted", action="store_true", help="skip the unfitted rows (smoke tests)")
    args = p.parse_args()
    t_all = time.perf_counter()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    data = build_dataset(Path(args.tarballs), Path(args.work), args.robot)
    robot = load_robot(args.robot)
    ds = load_dataset(str(data), robot)
    weights = ds.fit_weights()
    rate = ds.rate_hz
    dt = 1.0 / rate
    train = list(ds.split("train"))[:args.train_runs]
    val = list(ds.split("validation"))
    split_runs = {s: list(ds.split(s)) for s in SPLITS}
    print(f"{data}: {len(ds.trajectories)} runs at {rate:g} Hz; train {len(train)}, "
          + ", ".join(f"{s} {len(v)}" for s, v in split_runs.items())
          + f"; mujoco {mujoco.__version__}; windows {args.per_run} x {args.horizon} per training run", flush=True)

    def file_model():
        m = mujoco.MjModel.from_xml_path(args.robot)
        m.opt.timestep = dt
        return m

    # The reference every improvement is over: the robot file's PD model in MuJoCo C (the Playground fit's start).
    ref = {}
    for s in SPLITS:
        ref[s] = asdict(metrics(split_runs[s], replay(file_model(), split_runs[s]), weights))
    print("robot file's PD model (MuJoCo C): " + "  ".join(f"{s} {ref[s]['mean_abs_dq']:.4f}" for s in SPLITS),
          flush=True)

    def score(name, m, drive=None, delay=0.0):
        row = {}
        for s in SPLITS:
            t0 = time.perf_counter()
            runs = split_runs[s]
            if delay:
                runs = [dataclasses.replace(t, q_cmd=adapter.shift(t.q_cmd, delay, dt)) for t in runs]
            r = evaluate_baseline(m, runs, ref[s], drive, weights)
            row[s] = r
            print(f"{name:58s} {s:10s} mean |dq| {r['model']['mean_abs_dq']:.4f} ± {r['model']['std_abs_dq']:.4f} "
                  f"rad ({r['improvement']:.2f}x over the file's PD)  diverged {r['model']['diverged']}  "
                  f"{time.perf_counter() - t0:.1f} s", flush=True)
        return row

    unfitted = {}
    if not args.no_unfitted:
        bam32 = dataclasses.replace(BAM_STS3215_7V4, kp=32.0)
        unfitted["LeRobot's MuJoCo model (kp 17.8, as it is)"] = score(
            "LeRobot's MuJoCo model (kp 17.8, as it is)", lerobot_model(args.robot, rate))
        unfitted["BAM-style drive, STS3215 7.4 V m1, P 16 (LeRobot's)"] = score(
            "BAM-style drive, STS3215 7.4 V m1, P 16 (LeRobot's)", bam_model(args.robot, rate),
            lambda q0: BamDrive(BAM_STS3215_7V4, q0))
        unfitted["BAM-style drive, STS3215 7.4 V m1, P 32 (BAM's bench)"] = score(
            "BAM-style drive, STS3215 7.4 V m1, P 32 (BAM's bench)", bam_model(args.robot, rate, bam32),
            lambda q0: BamDrive(bam32, q0))

    fitted, records = {}, {}
    settings = {"horizon": args.horizon, "per_run": args.per_run, "max_iters": args.max_iters,
                "max_nfev": args.max_nfev, "threads": args.threads, "train_runs": len(train)}
    todo = args.only.split(",")

    def val_pd(spec_fit):
        def f(params):
            m = adapter.build(params, spec_fit)
            delay = float(params["delay"].value[0]) if "delay" in params else 0.0
            return adapter.mean_abs_dq(val, adapter.replay_q(m, val, delay, threads=args.threads))
        return f

    for key in ("playground", "lerobot"):
        if key not in todo:
            continue
        spec_fit = adapter.load_spec(args.robot, rate, contact=False)
        spec_score = adapter.load_spec(args.robot, rate, contact=True)
        if key == "lerobot":
            adapter.lerobot_spec(spec_fit)
            adapter.lerobot_spec(spec_score)
        params = adapter.playground_params(spec_fit) if key == "playground" else adapter.lerobot_params(spec_fit)
        ms = adapter.model_sequences(spec_fit, train, args.horizon, args.per_run)
        print(f"\n== {key}: {params.size} parameters, {len(ms.sensordata)} windows", flush=True)
        opt, rec = adapter.fit_sysid(params, ms, val_pd(spec_fit), delay=key == "playground",
                                     max_iters=args.max_iters, threads=args.threads)
        print(f"  {rec.method}: {rec.iterations} iterations, {rec.seconds:.0f} s, {rec.status}", flush=True)
        delay = float(opt["delay"].value[0]) if key == "playground" else 0.0
        name = ("MuJoCo Playground's recipe (24 joint parameters + delay, mujoco.sysid)" if key == "playground"
                else "LeRobot's MuJoCo model, joint parameters + kp fitted (mujoco.sysid)")
        fitted[key] = {"name": name, "scores": score(name, adapter.build(opt, spec_score), delay=delay)}
        records[key] = rec

    if "bam" in todo:
        base_fit = adapter.load_spec(args.robot, rate, contact=False).compile()
        windows = adapter.BamWindows(base_fit, train, args.horizon, args.per_run)

        def val_bam(bp):
            m = adapter.bam_native(base_fit, bp)
            controls = [adapter.bam_targets(t.q_cmd, t.q[0], bp.max_velocity, dt) for t in val]
            return adapter.mean_abs_dq(val, adapter.replay_q(m, val, controls=controls, threads=args.threads))

        print(f"\n== bam: {len(adapter.BAM_FIELDS)} parameters, {windows.x0.shape[0]} windows", flush=True)
        bp, rec = adapter.fit_bam(windows, BAM_STS3215_7V4, val_bam, max_nfev=args.max_nfev, threads=args.threads)
        print(f"  {rec.method}: {rec.iterations} evaluations, {rec.seconds:.0f} s, {rec.status}", flush=True)
        name = "BAM's STS3215 model class fitted (scipy least_squares on the MuJoCo replay)"
        fitted["bam"] = {"name": name, "scores": score(name, bam_model(args.robot, rate, bp),
                                                       lambda q0: BamDrive(bp, q0))}
        records["bam"] = rec

    wres = wresdyn_row(Path.cwd())
    mach = machine()

    def entry(key):
        sc, rec = fitted[key]["scores"], records[key]
        return {"heldout_error": sc["heldout"]["model"]["mean_abs_dq"], "ood_error": sc["ood"]["model"]["mean_abs_dq"],
                "seconds_to_final": round(rec.seconds, 1),
                "converged": {"value": rec.converged, "reason": rec.status},
                "samples_used": rec.samples, "machine": mach,
                "extras": {"name": fitted[key]["name"], "method": rec.method, "iterations": rec.iterations,
                           "validation_error": sc["validation"]["model"]["mean_abs_dq"],
                           "diverged": {s: sc[s]["model"]["diverged"] for s in SPLITS},
                           "fitted": rec.values, "validation_curve": rec.curve,
                           "samples_used_means": "recorded training samples in the residual (windows x horizon, "
                                                 "500 Hz), each evaluated every iteration"}}

    fights = {}
    if "playground" in fitted:
        fights["fight2_playground_recipe"] = {"playground_recipe": entry("playground"), "wresdyn_servo": wres}
    if "lerobot" in fitted or "bam" in fitted:
        f3 = {k + "_fitted": entry(k) for k in ("lerobot", "bam") if k in fitted}
        f3["wresdyn_servo"] = wres
        fights["fight3_fitted_baselines"] = f3
    summary = {"fields": list(FIELDS), "fights": fights,
               "unfitted": {n: {s: r[s]["model"]["mean_abs_dq"] for s in SPLITS} for n, r in unfitted.items()},
               "reference_file_pd_mujoco": {s: ref[s]["mean_abs_dq"] for s in SPLITS},
               "settings": settings, "dataset": str(data), "mujoco": mujoco.__version__,
               "wall_seconds": round(time.perf_counter() - t_all, 1)}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))

    print("\n| model | validation | held-out | OOD | held-out: peer / wresdyn |\n|---|---|---|---|---|")
    w_h = wres["heldout_error"]

    def line(name, v, h, o):
        print(f"| {name} | {v:.4f} | {h:.4f} | {o:.4f} | {h / w_h:.2f} |")

    line("robot file's PD model (MuJoCo C), unfitted", *(ref[s]["mean_abs_dq"] for s in SPLITS))
    for n, r in unfitted.items():
        line(n + ", unfitted", *(r[s]["model"]["mean_abs_dq"] for s in SPLITS))
    for k, f in fitted.items():
        line(f["name"], *(f["scores"][s]["model"]["mean_abs_dq"] for s in SPLITS))
    line(f"wresdyn servo model ({WRESDYN_RUN})", wres["extras"]["validation_error"], wres["heldout_error"],
         wres["ood_error"])
    print(f"\nwrote {out / 'summary.json'}; {time.perf_counter() - t_all:.0f} s in all", flush=True)


if __name__ == "__main__":
    main()
