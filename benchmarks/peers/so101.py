"""Peers on the real SO-101: MuJoCo Playground's identification recipe, LeRobot's MuJoCo model and BAM's STS3215
model class, each fitted on the training runs of wresdyn's servo benchmark, scored on its validation, held-out and
OOD runs like the published (unfitted) models of ``benchmarks/real/so101_baselines.py`` and like wresdyn's servo model.

Metric: mean |Δq| [rad] over the five arm joints and every sample of whole runs, open loop from the first recorded
state (:func:`wresdyn.evaluation.servo_baselines.evaluate_baseline`, MuJoCo C, the robot file's options). The data
is the import of ``benchmarks/real/so101_servo_real.sh`` (same command, same splits: 26 training, 6 validation, 6
held-out, 2 OOD runs); training runs fit, validation draws the curves and picks the Playground fit's iterate and
setting, held-out and OOD are scored once per model. The recipes and the adapter: ``so101_sysid.py`` beside this
file. wresdyn's row is read from its committed results (:data:`WRESDYN_RUN`, :data:`WRESDYN_RESIDUAL`), not rerun. The
unfitted rows and the three fits are independent: each runs in its own process (``--part``, ``parts/*.json``), then
one merge writes ``summary.json`` and the tables.

    PYTHONPATH=. python benchmarks/peers/so101.py --tarballs ../shared/real/so101 --work /tmp/peers_so101 \\
        --out benchmarks/results/peers/so101 | tee benchmarks/results/peers/so101/log.txt
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

import mujoco
import numpy as np

import host
import so101_residual
import so101_sysid as adapter

from wresdyn.data.dataset import load_dataset
from wresdyn.evaluation.open_loop import metrics
from wresdyn.evaluation.servo_baselines import (BAM_STS3215_7V4, BamDrive, bam_model, evaluate_baseline,
                                                lerobot_model, replay)
from wresdyn.robot.description import load_robot

SPLITS = ("validation", "heldout", "ood")
WRESDYN_RUN = "benchmarks/results/so101_servo/effort/k1e5_reset"
"""wresdyn's servo model as chosen on validation (the damper friction law's rate 1e5 /s, the effort reset; seed 0):
its ``identify.log`` and ``config.json``, and its ``eval_metrics.json`` when no residual is on top."""
WRESDYN_RESIDUAL: str | None = "benchmarks/results/so101_servo/hybrid/gru_delta"
"""The residual network fitted on that servo model (``wresdyn fit --physics``), kept where validation chose the hybrid
over the servo model alone: its ``eval_metrics.json`` scores wresdyn's row and its ``train_summary.json`` adds its
time and samples; ``None`` = the servo model alone."""
FIELDS = ("heldout_error", "ood_error", "seconds_to_final", "converged", "samples_used", "machine")


def build_dataset(tarballs: Path, work: Path, robot: str) -> Path:
    """The servo benchmark's import (``benchmarks/real/so101_servo_real.sh``'s ``collect`` line), built once."""
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
    return f"{os.cpu_count()} CPU cores ({host.cpu_model()}); load average at start {host.load_average()}"


def wresdyn_row(root: Path) -> dict:
    """wresdyn's model from its committed files: the servo model's time from the ``done: N s`` line of
    ``identify.log`` and its windows from ``config.json``; with :data:`WRESDYN_RESIDUAL`, the residual's training
    time and samples added from its ``train_summary.json``; the errors from the scored model's
    ``eval_metrics.json``."""
    run = root / WRESDYN_RUN
    cfg = json.loads((run / "config.json").read_text())["sysid"]
    log = (run / "identify.log").read_text()
    done = [line for line in log.splitlines() if line.startswith("done:")]
    seconds = float(done[-1].split()[1]) if done else None
    per_stage = cfg["iterations"] // len(cfg["horizon_curriculum"])
    samples = cfg["windows"] * per_stage * sum(cfg["horizon_curriculum"])
    reason = (f"fixed budget of {cfg['iterations']} Adam iterations (no stopping rule), the iterate chosen by "
              "validation, then the effort-limit reset")
    scored, source = run, f"{WRESDYN_RUN}/eval_metrics.json, identify.log, config.json"
    if WRESDYN_RESIDUAL:
        scored = root / WRESDYN_RESIDUAL
        fit = json.loads((scored / "train_summary.json").read_text())
        seconds = None if seconds is None else round(seconds + fit["residual_wall_s"], 1)
        samples += fit["sim_steps"] // 2  # the fit counts each window step twice, forward and backward
        reason += (f"; the residual fitted on it until validation plateaued ({fit['iterations']} iterations), its "
                   "iterate chosen by validation")
        source = (f"{WRESDYN_RUN}/identify.log, config.json; {WRESDYN_RESIDUAL}/eval_metrics.json, "
                  "train_summary.json")
    ev = json.loads((scored / "eval_metrics.json").read_text())["splits"]
    return {
        "heldout_error": ev["heldout"]["pd_residual"]["mean_abs_dq"],
        "ood_error": ev["ood"]["pd_residual"]["mean_abs_dq"],
        "seconds_to_final": seconds,
        "converged": {"value": False, "reason": reason},
        "samples_used": samples,
        "machine": "2 CPU cores (AMD EPYC), shared with other jobs (the wall clock of identify.log"
                   + (" and train_summary.json)" if WRESDYN_RESIDUAL else ")"),
        "extras": {"source": source,
                   "validation_error": ev["validation"]["pd_residual"]["mean_abs_dq"],
                   "samples_used_means": "window samples stepped over the run with repeats: windows x iterations "
                                         "per horizon stage x sum of the horizons (identification), plus the "
                                         "residual fit's window steps"},
    }


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--tarballs", default="../shared/real/so101", help="folder with so101-sage-logs.tar.xz")
    p.add_argument("--work", default="/tmp/peers_so101", help="scratch folder for the import")
    p.add_argument("--out", default="benchmarks/results/peers/so101")
    p.add_argument("--robot", default="scenes/so101/so101.xml")
    p.add_argument("--horizon", type=int, default=1000, help="fit window length [samples at 500 Hz]")
    p.add_argument("--per-run", type=int, default=1, help="fit windows per training run, evenly spaced")
    p.add_argument("--max-iters", type=int, default=20, help="mujoco.sysid's iteration cap")
    p.add_argument("--max-nfev", type=int, default=60, help="scipy least_squares' evaluation cap (BAM)")
    p.add_argument("--threads", type=int, default=1, help="mujoco.rollout threads per part")
    p.add_argument("--train-runs", type=int, default=None, help="only the first N training runs (smoke tests)")
    p.add_argument("--only", default=",".join(PARTS), help=f"parts to run, of {','.join(PARTS)}")
    p.add_argument("--residual", choices=("radians", "normalised"), default="radians",
                   help="the Playground and LeRobot fits' residual: arm-joint position error in radians, or "
                        "mujoco.sysid's default (each column divided by its window's RMS value)")
    p.add_argument("--pick", choices=("validation", "last"), default="validation",
                   help="the Playground fit's reported iterate: the one of lowest validation error, or the last")
    p.add_argument("--tag", default="", help="suffix of the part's file (parts/KEY_TAG.json), so settings coexist")
    p.add_argument("--merge", action="store_true", help="only merge the parts already in OUT/parts")
    p.add_argument("--part", action="store_true", help="run the one part of --only here (the parallel runner's "
                                                          "call) instead of spawning every part and merging")
    return p.parse_args()


PARTS = ("unfitted", "playground", "lerobot", "bam")
"""Each part is its own process (the fits are independent); the merge reads their ``parts/*.json``."""


def run_part(key: str, args) -> None:
    data = build_dataset(Path(args.tarballs), Path(args.work), args.robot)
    robot = load_robot(args.robot)
    ds = load_dataset(str(data), robot)
    weights = ds.fit_weights()
    rate = ds.rate_hz
    dt = 1.0 / rate
    train = list(ds.split("train"))[:args.train_runs]
    val = list(ds.split("validation"))
    split_runs = {s: list(ds.split(s)) for s in SPLITS}
    no_ref = {s: {"mean_abs_dq": float("nan")} for s in SPLITS}  # ratios are taken at the merge
    print(f"[{key}] {data}: {len(ds.trajectories)} runs at {rate:g} Hz; train {len(train)}, "
          + ", ".join(f"{s} {len(v)}" for s, v in split_runs.items())
          + f"; mujoco {mujoco.__version__}", flush=True)

    def score(name, m, drive=None, delay=0.0):
        row = {}
        for s in SPLITS:
            t0 = time.perf_counter()
            runs = split_runs[s]
            if delay:
                runs = [dataclasses.replace(t, q_cmd=adapter.shift(t.q_cmd, delay, dt)) for t in runs]
            r = evaluate_baseline(m, runs, no_ref[s], drive, weights)["model"]
            row[s] = r
            print(f"[{key}] {name:58s} {s:10s} mean |dq| {r['mean_abs_dq']:.4f} ± {r['std_abs_dq']:.4f} rad  "
                  f"diverged {r['diverged']}  {time.perf_counter() - t0:.1f} s", flush=True)
        return row

    part = {"key": key, "machine": machine()}
    if key == "unfitted":
        m = mujoco.MjModel.from_xml_path(args.robot)
        m.opt.timestep = dt
        bam32 = dataclasses.replace(BAM_STS3215_7V4, kp=32.0)
        part["rows"] = {
            REF: score(REF, m),
            "LeRobot's MuJoCo model (kp 17.8, as it is)": score(
                "LeRobot's MuJoCo model (kp 17.8, as it is)", lerobot_model(args.robot, rate)),
            "BAM-style drive, STS3215 7.4 V m1, P 16 (LeRobot's)": score(
                "BAM-style drive, STS3215 7.4 V m1, P 16 (LeRobot's)", bam_model(args.robot, rate),
                lambda q0: BamDrive(BAM_STS3215_7V4, q0)),
            "BAM-style drive, STS3215 7.4 V m1, P 32 (BAM's bench)": score(
                "BAM-style drive, STS3215 7.4 V m1, P 32 (BAM's bench)", bam_model(args.robot, rate, bam32),
                lambda q0: BamDrive(bam32, q0)),
        }
    elif key in ("playground", "lerobot"):
        spec_fit = adapter.load_spec(args.robot, rate, contact=False)
        spec_score = adapter.load_spec(args.robot, rate, contact=True)
        if key == "lerobot":
            adapter.lerobot_spec(spec_fit)
            adapter.lerobot_spec(spec_score)
        params = adapter.playground_params(spec_fit) if key == "playground" else adapter.lerobot_params(spec_fit)
        ms = adapter.model_sequences(spec_fit, train, args.horizon, args.per_run)
        print(f"[{key}] {params.size} parameters, {len(ms.sensordata)} windows of {args.horizon}", flush=True)

        def val_pd(params):
            m = adapter.build(params, spec_fit)
            delay = float(params["delay"].value[0]) if "delay" in params else 0.0
            return adapter.mean_abs_dq(val, adapter.replay_q(m, val, delay, threads=args.threads))

        residual = so101_residual.radian_residual if args.residual == "radians" else None
        opt, rec = adapter.fit_sysid(params, ms, val_pd, delay=key == "playground", max_iters=args.max_iters,
                                     threads=args.threads, log=lambda *a, **k: print(f"[{key}]", *a, **k),
                                     modify_residual=residual)
        print(f"[{key}] {rec.method}: {rec.seconds:.0f} s, {rec.status}", flush=True)
        last = rec.curve[-1]
        part["last_iterate"] = {"iteration": last["iteration"], "validation": last["validation"]}
        if key == "playground" and args.pick == "validation":
            # Gauss-Newton lowers the training objective, not the whole-run error: validation picks the iterate
            best = min(rec.curve, key=lambda c: c["validation"])
            for k, v in best["values"].items():
                opt[k].update_from_vector(np.asarray(v))
            rec.values = best["values"]
            part["picked_iterate"] = {"iteration": best["iteration"], "validation": best["validation"]}
            print(f"[{key}] picked iterate {best['iteration']} (validation {best['validation']:.5f} rad; last "
                  f"{last['validation']:.5f} rad)", flush=True)
        delay = float(opt["delay"].value[0]) if key == "playground" else 0.0
        part["name"] = NAMES[key]
        part["scores"] = score(NAMES[key], adapter.build(opt, spec_score), delay=delay)
        part["record"] = asdict(rec)
    elif key == "bam":
        base_fit = adapter.load_spec(args.robot, rate, contact=False).compile()
        windows = adapter.BamWindows(base_fit, train, args.horizon, args.per_run)

        def val_bam(bp):
            m = adapter.bam_native(base_fit, bp)
            controls = [adapter.bam_targets(t.q_cmd, t.q[0], bp.max_velocity, dt) for t in val]
            return adapter.mean_abs_dq(val, adapter.replay_q(m, val, controls=controls, threads=args.threads))

        print(f"[{key}] {len(adapter.BAM_FIELDS)} parameters, {windows.x0.shape[0]} windows of {args.horizon}",
              flush=True)
        bp, rec = adapter.fit_bam(windows, BAM_STS3215_7V4, val_bam, max_nfev=args.max_nfev, threads=args.threads,
                                  log=lambda *a, **k: print(f"[{key}]", *a, **k))
        print(f"[{key}] {rec.method}: {rec.seconds:.0f} s, {rec.status}", flush=True)
        part["name"] = NAMES[key]
        part["scores"] = score(NAMES[key], bam_model(args.robot, rate, bp), lambda q0: BamDrive(bp, q0))
        part["record"] = asdict(rec)
    else:
        raise ValueError(f"unknown part {key!r}; parts: {PARTS}")
    part["settings"] = {"horizon": args.horizon, "per_run": args.per_run, "max_iters": args.max_iters,
                        "max_nfev": args.max_nfev, "threads": args.threads, "train_runs": len(train),
                        "residual": args.residual, "pick": args.pick}
    part["dataset"] = str(data)
    parts = Path(args.out) / "parts"
    parts.mkdir(parents=True, exist_ok=True)
    name = f"{key}_{args.tag}" if args.tag else key
    (parts / f"{name}.json").write_text(json.dumps(part, indent=2))


OLD_MACHINE = "2 CPU cores (AMD EPYC), shared with other jobs"
"""The machine of the parts written before each part recorded its own (their MANIFEST gives the load)."""
REF = "robot file's PD model (MuJoCo C)"
"""The reference of every ratio: ``scenes/so101/so101.xml`` as it is (the Playground fit's start)."""
NAMES = {
    "playground": "MuJoCo Playground's recipe (24 joint parameters + delay, mujoco.sysid)",
    "lerobot": "LeRobot's MuJoCo model, joint parameters + kp fitted (mujoco.sysid)",
    "bam": "BAM's STS3215 model class fitted (scipy least_squares on the MuJoCo replay)",
}


def merge(args, wall: float | None) -> None:
    """``summary.json`` and the table from the parts."""
    out = Path(args.out)
    parts = {p.stem: json.loads(p.read_text()) for p in sorted((out / "parts").glob("*.json"))}
    wres = wresdyn_row(Path.cwd())

    def entry(part):
        sc, rec = part["scores"], part["record"]
        return {"heldout_error": sc["heldout"]["mean_abs_dq"], "ood_error": sc["ood"]["mean_abs_dq"],
                "seconds_to_final": round(rec["seconds"], 1),
                "converged": {"value": rec["converged"], "reason": rec["status"]},
                "samples_used": rec["samples"], "machine": part.get("machine", OLD_MACHINE),
                "extras": {"name": part["name"], "method": rec["method"], "iterations": rec["iterations"],
                           "validation_error": sc["validation"]["mean_abs_dq"],
                           "diverged": {s: sc[s]["diverged"] for s in SPLITS}, "fitted": rec["values"],
                           "validation_curve": rec["curve"], "settings": part["settings"],
                           "samples_used_means": "recorded training samples in the residual (windows x horizon at "
                                                 "500 Hz), every one evaluated at every iteration"}}

    fights = {}
    # several window settings of the Playground recipe (parts/playground*.json): validation picks the one reported
    configs = {k: v for k, v in parts.items() if k.startswith("playground")}
    if configs:
        chosen = min(configs, key=lambda k: configs[k]["scores"]["validation"]["mean_abs_dq"])
        e = entry(configs[chosen])
        e["extras"]["chosen_by_validation_from"] = {
            k: {"settings": v["settings"], **{f"{s}_error": v["scores"][s]["mean_abs_dq"] for s in SPLITS},
                "seconds_to_final": round(v["record"]["seconds"], 1), "converged": v["record"]["converged"],
                "status": v["record"]["status"], "samples_used": v["record"]["samples"]}
            for k, v in configs.items()}
        fights["fight2_playground_recipe"] = {"playground_recipe": e, "wresdyn_servo": wres}
    f3 = {f"{k}_fitted": entry(parts[k]) for k in ("lerobot", "bam") if k in parts}
    if f3:
        f3["wresdyn_servo"] = wres
        fights["fight3_fitted_baselines"] = f3
    rows = parts.get("unfitted", {}).get("rows", {})
    summary = {"fields": list(FIELDS), "fights": fights,
               "unfitted": {n: {s: r[s]["mean_abs_dq"] for s in SPLITS} for n, r in rows.items()},
               "mujoco": mujoco.__version__, "wall_seconds_all_parts": None if wall is None else round(wall, 1),
               "dataset": next(iter(parts.values()))["dataset"] if parts else None}
    (out / "summary.json").write_text(json.dumps(summary, indent=2))

    ref = rows.get(REF)
    w_h, w_o = wres["heldout_error"], wres["ood_error"]
    print("\n| model | validation | held-out | OOD | held-out vs file's PD | held-out / wresdyn's | OOD / wresdyn's |"
          "\n|---|---|---|---|---|---|---|")

    def line(name, sc):
        v, h, o = (sc[s] for s in SPLITS)
        r = f"{ref['heldout']['mean_abs_dq'] / h:.2f}x" if ref else "-"
        print(f"| {name} | {v:.4f} | {h:.4f} | {o:.4f} | {r} | {h / w_h:.2f} | {o / w_o:.2f} |")

    for n, r in rows.items():
        line(n + ", unfitted", {s: r[s]["mean_abs_dq"] for s in SPLITS})
    for k, part in parts.items():
        if k != "unfitted":
            st = part["settings"]
            cap = st["max_nfev"] if k == "bam" else st["max_iters"]
            residual = f", residual {st['residual']}" if "residual" in st else ""
            line(f"{part['name']}, windows {st['per_run']} x {st['horizon']}, cap {cap}{residual}",
                 {s: part["scores"][s]["mean_abs_dq"] for s in SPLITS})
    line(f"wresdyn ({WRESDYN_RESIDUAL or WRESDYN_RUN})", {"validation": wres["extras"]["validation_error"],
                                                  "heldout": w_h, "ood": w_o})
    print("\n| fit | seconds to final | converged | samples used |\n|---|---|---|---|")
    for fight in fights.values():
        for k, e in fight.items():
            if k != "wresdyn_servo":
                print(f"| {e['extras']['name']} | {e['seconds_to_final']} | {e['converged']['value']}: "
                      f"{e['converged']['reason']} | {e['samples_used']} |")
    print(f"| wresdyn | {wres['seconds_to_final']} | {wres['converged']['value']}: "
          f"{wres['converged']['reason']} | {wres['samples_used']} |")
    print(f"\nwrote {out / 'summary.json'}", flush=True)


def main() -> None:
    args = parse_args()
    keys = args.only.split(",")
    if args.part:
        run_part(keys[0], args)
        return
    if args.merge:
        merge(args, None)
        return
    t0 = time.perf_counter()
    build_dataset(Path(args.tarballs), Path(args.work), args.robot)
    passed = ["--tarballs", args.tarballs, "--work", args.work, "--out", args.out, "--robot", args.robot,
              "--horizon", str(args.horizon), "--per-run", str(args.per_run), "--max-iters", str(args.max_iters),
              "--max-nfev", str(args.max_nfev), "--threads", str(args.threads), "--residual", args.residual,
              "--pick", args.pick] + (["--tag", args.tag] if args.tag else [])
    if args.train_runs:
        passed += ["--train-runs", str(args.train_runs)]
    procs = [subprocess.Popen([sys.executable, __file__, *passed, "--only", k, "--part"]) for k in keys]
    codes = [p.wait() for p in procs]
    if any(codes):
        raise SystemExit(f"parts {keys} exited with {codes}")
    merge(args, time.perf_counter() - t0)
    print(f"{time.perf_counter() - t0:.0f} s in all", flush=True)


if __name__ == "__main__":
    main()
