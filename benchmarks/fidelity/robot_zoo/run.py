"""The robot zoo: ``wresdyn collect`` then ``wresdyn fit --eval`` on every robot of ``robots.toml``, defaults only.

Each robot differs only in its model file, its gains file and its output folder: the default mismatch, the
default dataset sizes and the default fit. Per robot ``OUT/<robot>/`` holds ``data/`` (the dataset and
``collect.log``), ``fit/`` (the run folder, ``fit.log``, ``eval/metrics.json``), each command's whole terminal
output (``collect.out``, ``fit.out``) and ``result.json``; a robot whose ``result.json`` exists is skipped, one whose
dataset exists is not recorded again (the fit resumes its checkpoint). ``OUT/commands.txt`` lists every command run,
``OUT/summary.json`` one entry per finished robot:

* ``source``: the model's package, file and upstream; ``dof``: its actuated joints;
* ``heldout_ratio``, ``ood_ratio``, ``validation_ratio``: mean |dq| of PD only over PD + residual on that split
  (the fit's ``eval/metrics.json``, ``improvement``);
* ``fit_seconds``: wall-clock of the ``wresdyn fit --eval`` command (kernel compile, identification, residual,
  evaluation); the fit's own training time is ``train_wall_s`` in ``result.json``;
* ``device``: the device the fit ran on.

``--smoke`` records and fits at tiny sizes (the only size flags passed), to check the path in minutes.

    python benchmarks/fidelity/robot_zoo/run.py [--robots g1,ur5] [--smoke] [--out DIR] [--device cpu]
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import subprocess
import sys
import sysconfig
import time
from datetime import datetime, timezone
from pathlib import Path

from zoo import ZooRobot, load_zoo

REPO = Path(__file__).resolve().parents[3]
DEFAULT_OUT = REPO / "benchmarks" / "results" / "robot_zoo"
SITE = Path(sysconfig.get_paths()["purelib"])
SMOKE_COLLECT = ("--train", "2", "--validation", "1", "--heldout", "1", "--ood", "1", "--duration", "1")
"""Smoke sizes of the recording: one trajectory per evaluation split, 1 s each."""
SMOKE_FIT = ("--iterations", "4", "--windows", "4", "--curriculum", "8", "--identify-iterations", "4")
"""Smoke sizes of the fit: a few iterations of each stage on short windows."""
SUMMARY_FIELDS = ("source", "dof", "heldout_ratio", "ood_ratio", "validation_ratio", "fit_seconds", "device")


def _shown(arg: str) -> str:
    """An argument as ``commands.txt`` writes it, free of this machine's paths: this interpreter as ``python``, a
    path in the checkout relative to its root, a path in the environment's packages from ``<site-packages>``."""
    if arg == sys.executable:
        return "python"
    for root, name in ((SITE, "<site-packages>"), (REPO, None)):
        try:
            rel = Path(arg).relative_to(root)
        except ValueError:
            continue
        return str(rel) if name is None else f"{name}/{rel}"
    return arg


def _run(cmd: list[str], log: Path, commands: Path) -> float:
    """Run ``cmd`` (from the repository root), its output into ``log``; returns its wall-clock [s]."""
    line = " ".join(shlex.quote(_shown(c)) for c in cmd)
    with commands.open("a") as f:
        f.write(f"{datetime.now(timezone.utc):%Y-%m-%d %H:%M:%S} UTC  {line}\n")
    print(f"$ {line}", flush=True)
    start = time.perf_counter()
    with log.open("w") as f:
        rc = subprocess.run(cmd, cwd=REPO, stdout=f, stderr=subprocess.STDOUT).returncode
    wall = time.perf_counter() - start
    if rc != 0:
        tail = log.read_text().strip().splitlines()[-3:]
        raise RuntimeError(f"exit {rc} after {wall:.0f} s ({log}): " + " | ".join(tail))
    return wall


def run_robot(z: ZooRobot, out: Path, smoke: bool, device: str, commands: Path) -> dict:
    """Collect and fit one robot into ``out``; its ``result.json``."""
    wresdyn = [sys.executable, "-m", "wresdyn"]
    data = out / "data"
    if not (data / "dataset.npz").is_file():
        collect = [*wresdyn, "collect", "--robot", str(z.path), "--gains", str(z.gains), "--out", str(data), "--quiet"]
        _run(collect + list(SMOKE_COLLECT if smoke else ()), out / "collect.out", commands)
    fit = [*wresdyn, "fit", str(data / "dataset.npz"), "--eval", "--out", str(out / "fit"), "--quiet"]
    if device != "cpu":
        fit += ["--device", device]
    wall = _run(fit + list(SMOKE_FIT if smoke else ()), out / "fit.out", commands)
    metrics = json.loads((out / "fit" / "eval" / "metrics.json").read_text())["splits"]
    train = json.loads((out / "fit" / "train_summary.json").read_text())
    result = {
        "source": f"{z.package} {z.version}: {z.file} ({z.source}; licence {z.licence})",
        "dof": z.dof,
        **{f"{s}_ratio": metrics[s]["improvement"] for s in ("heldout", "ood", "validation")},
        "fit_seconds": round(wall, 1),
        "device": device,
        "pd_only_rad": {s: metrics[s]["pd_only"]["mean_abs_dq"] for s in ("validation", "heldout", "ood")},
        "pd_residual_rad": {s: metrics[s]["pd_residual"]["mean_abs_dq"] for s in ("validation", "heldout", "ood")},
        "train_wall_s": train["wall_s"],
        "smoke": smoke,
    }
    (out / "result.json").write_text(json.dumps(result, indent=2) + "\n")
    return result


def write_manifest(out: Path, names: list[str], smoke: bool, device: str) -> None:
    """Append this invocation's provenance to ``OUT/MANIFEST.md``: commit, packages, machine, sizes."""
    import importlib.metadata
    import platform

    def version(pkg: str) -> str:
        try:
            return importlib.metadata.version(pkg)
        except importlib.metadata.PackageNotFoundError:
            return "not installed"

    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True).stdout
    dirty = subprocess.run(["git", "status", "--porcelain", "--", "wresdyn", "benchmarks/fidelity/robot_zoo"], cwd=REPO,
                           capture_output=True, text=True).stdout.strip()
    cpu = next((ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                if ln.startswith("model name")), platform.processor()) if Path("/proc/cpuinfo").exists() else ""
    packages = ", ".join(f"{p} {version(p)}" for p in ("example-robot-data", "newton", "warp-lang", "mujoco", "torch"))
    sizes = f"smoke ({' '.join(SMOKE_COLLECT)} / {' '.join(SMOKE_FIT)})" if smoke else "defaults"
    lines = [f"## {datetime.now(timezone.utc):%Y-%m-%d %H:%M} UTC: {', '.join(names)}", "",
             f"- command: `python benchmarks/fidelity/robot_zoo/run.py {' '.join(sys.argv[1:])}`",
             f"- sizes: {sizes}; device {device}",
             f"- commit {commit.strip()}{' with uncommitted changes' if dirty else ''}; {packages}",
             f"- machine: {os.cpu_count()} CPU cores ({cpu}), Python {platform.python_version()}", ""]
    path = out / "MANIFEST.md"
    head = "" if path.exists() else ("# Robot zoo raw output\n\nWritten by `benchmarks/fidelity/robot_zoo/run.py`, one "
                                     "section per invocation; every command in `commands.txt`.\n\n")
    with path.open("a") as f:
        f.write(head + "\n".join(lines) + "\n")


def write_summary(out: Path, zoo: dict[str, ZooRobot]) -> dict:
    """``summary.json`` from every robot's ``result.json`` under ``out`` (robots of earlier invocations included)."""
    summary = {}
    for name in zoo:
        f = out / name / "result.json"
        if f.is_file():
            r = json.loads(f.read_text())
            summary[name] = {k: r[k] for k in SUMMARY_FIELDS}
    (out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", default=None, help="comma-separated robot names (default: every robot of robots.toml)")
    p.add_argument("--smoke", action="store_true", help="tiny sizes (minutes, not a result)")
    p.add_argument("--out", default=str(DEFAULT_OUT), help="output folder (default: benchmarks/results/robot_zoo/)")
    p.add_argument("--device", default="cpu", help="the fit's device (default: cpu)")
    args = p.parse_args(argv)
    zoo = load_zoo()
    names = args.robots.split(",") if args.robots else list(zoo)
    unknown = [n for n in names if n not in zoo]
    if unknown:
        p.error(f"unknown robot(s) {unknown}; robots.toml has {list(zoo)}")
    out = Path(args.out).resolve()
    out.mkdir(parents=True, exist_ok=True)
    commands = out / "commands.txt"
    os.environ.setdefault("PYTHONPATH", str(REPO))  # the commands import this checkout's wresdyn
    write_manifest(out, names, args.smoke, args.device)
    failed = {}
    for name in names:
        robot_out = out / name
        if (robot_out / "result.json").is_file():
            print(f"{name}: {robot_out / 'result.json'} exists, skipped", flush=True)
            continue
        robot_out.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        try:
            r = run_robot(zoo[name], robot_out, args.smoke, args.device, commands)
        except (RuntimeError, FileNotFoundError, KeyError, TypeError) as e:
            failed[name] = str(e)
            (robot_out / "error.txt").write_text(str(e) + "\n")
            print(f"{name}: FAILED {e}", flush=True)
            continue
        print(f"{name}: {r['dof']} DoF  held-out {r['heldout_ratio']:.2f}x  OOD {r['ood_ratio']:.2f}x  validation "
              f"{r['validation_ratio']:.2f}x  fit {r['fit_seconds']:.0f} s ({time.perf_counter() - start:.0f} s with "
              "the recording)", flush=True)
    summary = write_summary(out, zoo)
    print(f"wrote {out / 'summary.json'} ({len(summary)} robots)"
          + (f"; failed: {', '.join(failed)}" if failed else ""))
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main())
