"""Does the identifiability report flag the stand's unsaturated effort limits on the shipped humanoid's default data,
and clear them on data recorded with ``--probe-saturation``?

One command: records the probe dataset (``wresdyn collect --probe-saturation 6``: the shipped data's 16 training
trajectories bit for bit, plus 6 probes), identifies both with the default settings (``wresdyn identify``; the same
``--identify-iterations N`` for both if given), and writes ``default.json`` and ``probe.json`` (each run's
``identifiability.json`` without its correlation matrix, which stays in the run folder), ``summary.md`` and
``MANIFEST.md`` to the results folder::

    python benchmarks/fidelity/identifiability.py [--out runs/identifiability] [--results benchmarks/results/identifiability]
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import subprocess
import sys
from pathlib import Path


def sh(cmd: list[str], log: list[str]) -> None:
    """Run a command of the benchmark, recorded in the manifest."""
    log.append(" ".join(cmd))
    print("$", " ".join(cmd), flush=True)
    subprocess.run(cmd, check=True)


def effort_flags(found: dict) -> list[str]:
    """The joints whose effort limit the report flags as never reached."""
    return [p.split(":", 1)[1] for f in found["flags"] if f["kind"] == "unexcited_effort" for p in f["parameters"]]


def identify_seconds(run: Path) -> float:
    """The identification's training wall-clock [s] from the run's log (``done: N s``)."""
    m = re.findall(r"^done: (\d+) s", (run / "identify.log").read_text(), re.M)
    return float(m[-1]) if m else float("nan")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--data", default="data/dataset.npz", help="the default data (the shipped dataset)")
    p.add_argument("--out", default="runs/identifiability", help="runs and the probe dataset (not in git)")
    p.add_argument("--results", default="benchmarks/results/identifiability", help="small outputs (in git)")
    p.add_argument("--identify-iterations", type=int, default=None,
                   help="a fixed Adam count for both identifications (default: until validation plateaus)")
    args = p.parse_args()
    out, results = Path(args.out), Path(args.results)
    results.mkdir(parents=True, exist_ok=True)
    py = [sys.executable, "-m", "wresdyn"]
    commands: list[str] = []
    probe_data = out / "probe_data" / "dataset.npz"
    collect = [*py, "collect", "--probe-saturation", "6", "--no-gap", "--quiet", "--out", str(probe_data.parent)]
    if probe_data.exists():
        commands.append(" ".join(collect) + "   # (the dataset was there already: not rerun)")
    else:
        sh(collect, commands)
    fixed = [] if args.identify_iterations is None else ["--iterations", str(args.identify_iterations)]
    found, seconds = {}, {}
    for name, data in (("default", args.data), ("probe", str(probe_data))):
        run = out / name
        sh([*py, "identify", data, "--out", str(run), "--quiet", *fixed], commands)
        full = json.loads((run / "identifiability.json").read_text())
        full.pop("correlation")
        (results / f"{name}.json").write_text(json.dumps(full, indent=1))
        found[name], seconds[name] = full, (identify_seconds(run), full["seconds"])
    flagged, after = effort_flags(found["default"]), effort_flags(found["probe"])
    cleared = [j for j in flagged if j not in after]
    lines = ["# Identifiability: default data against the saturation probe", "",
             "| data | identification [s] | report [s] | effort limits flagged unexcited |", "|---|---|---|---|"]
    for name in ("default", "probe"):
        lines.append(f"| {name} | {seconds[name][0]:.0f} | {seconds[name][1]:.1f} | "
                     f"{', '.join(effort_flags(found[name])) or '-'} |")
    lines += ["", f"Cleared by the probe: {', '.join(cleared) or 'none'}.",
              f"Still flagged with the probe: {', '.join(after) or 'none'}.",
              f"Newly flagged with the probe: {', '.join(j for j in after if j not in flagged) or 'none'}.", ""]
    (results / "summary.md").write_text("\n".join(lines))
    commit = subprocess.run(["git", "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    manifest = ["# identifiability", "", f"- commit: {commit}", f"- date: {datetime.date.today()}",
                f"- machine: {platform.machine()}, {os.cpu_count()} CPUs ({platform.platform()}), shared with other "
                "jobs", "- command: `python benchmarks/fidelity/identifiability.py`"
                + (f" --identify-iterations {args.identify_iterations}" if fixed else ""), "- steps it ran:", "",
                *[f"      {c}" for c in commands], "",
                "`default.json`, `probe.json`: the runs' `identifiability.json` without the correlation matrix (in the "
                "run folders); `summary.md`: the table.", ""]
    (results / "MANIFEST.md").write_text("\n".join(manifest))
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
