"""The floor benchmark's figures per mismatch and policy, over seeds: ``summary.json`` and a table with 95 % intervals.

    python benchmarks/skills/floor_fair.py OUT --default RUN0 RUN1 RUN2 --uneven RUN0 RUN1 RUN2

Each ``RUN`` is a ``wresdyn deploy --floor`` output folder (its ``results.json``). Writes ``OUT/summary.json``: per
mismatch and policy (``a``–``f``, the letters of the benchmark's policies), ``success`` (held-out, mean over seeds,
0–1), ``falls`` (held-out falls, mean over seeds), ``mpjpe_mrad`` and ``gmpjpe_mm`` (held-out, mean over seeds),
``worlds`` (the worlds the policy trained on), ``iterations`` (PPO iterations behind it: (a)'s plus its own
fine-tuning) and ``seeds``; and ``OUT/table.md``: the same with the success's 95 % interval (Wilson's, over every
held-out motion of every seed), the falls, drifts and divergences, and the gap closed on g-MPJPE against the oracle.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

FIELDS = ("success", "falls", "mpjpe_mrad", "gmpjpe_mm", "worlds", "iterations", "seeds")
"""The fields of each policy's entry in ``summary.json``, in order."""


def wilson(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson's score interval of a success rate (95 % for ``z`` = 1.96); (nan, nan) for no trials."""
    if n == 0:
        return float("nan"), float("nan")
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def _mean(xs) -> float:
    return float(sum(xs) / len(xs))


def _count(mean: dict, key: str, cause: str) -> float:
    """A failure count of a policy's mean metrics (runs before the counts were split name it by cause only)."""
    return float(mean[key]) if key in mean else float(mean.get("causes", {}).get(cause, 0))


def _worlds_iterations(run: dict, policy: str) -> tuple[int, int]:
    cfg = run["config"]
    worlds = cfg.get("num_worlds", cfg.get("envs"))
    oracle = cfg.get("oracle_num_worlds", cfg.get("oracle_envs")) or worlds
    if policy == "a_nominal":
        return int(worlds), int(cfg["iterations"])
    return int(oracle if policy == "d_oracle" else worlds), int(cfg["iterations"]) + int(cfg["finetune"])


def summarise(runs: list[dict]) -> tuple[dict, dict]:
    """``summary.json``'s entries of one mismatch (by policy letter) and the table's extra figures."""
    summary, extra = {}, {}
    for policy in runs[0]["policies"]:
        means = [r["real"]["heldout"][policy]["mean"] for r in runs]
        motions = [m for r in runs for m in r["real"]["heldout"][policy]["motions"]]
        worlds, iterations = zip(*(_worlds_iterations(r, policy) for r in runs))
        if len(set(worlds)) > 1 or len(set(iterations)) > 1:
            raise SystemExit(f"{policy}: the seeds ran at different sizes ({worlds}, {iterations})")
        summary[policy[0]] = {
            "success": _mean([m["success"] for m in means]), "falls": _mean([m.get("falls", 0) for m in means]),
            "mpjpe_mrad": 1e3 * _mean([m["mpjpe"] for m in means]),
            "gmpjpe_mm": 1e3 * _mean([m["g_mpjpe"] for m in means]),
            "worlds": worlds[0], "iterations": iterations[0], "seeds": [int(r["config"]["seed"]) for r in runs]}
        ok = round(sum(m["success"] for m in motions))
        extra[policy[0]] = {"name": policy, "ok": ok, "n": len(motions), "interval": wilson(ok, len(motions)),
                            "drifts": _mean([_count(m, "drifts", "drifted") for m in means]),
                            "diverged": _mean([_count(m, "diverged", "diverged") for m in means])}
    if "a" in summary and "d" in summary:
        a, d = summary["a"]["gmpjpe_mm"], summary["d"]["gmpjpe_mm"]
        for k, s in summary.items():
            extra[k]["gap_g_mpjpe"] = (a - s["gmpjpe_mm"]) / (a - d) if a > d else None
    return summary, extra


def table(name: str, summary: dict, extra: dict) -> list[str]:
    lines = [f"## {name} mismatch, held-out motions on the real robot's floor\n",
             "| policy | success (95 % interval) | falls | drifts | diverged | MPJPE [mrad] | g-MPJPE [mm] | gap closed "
             "(g-MPJPE) | worlds | iterations | seeds |", "|---|---|---|---|---|---|---|---|---|---|---|"]
    for k, s in summary.items():
        e = extra[k]
        lo, hi = e["interval"]
        gap = e.get("gap_g_mpjpe")
        gap_s = "—" if gap is None else f"{100 * gap:.0f} %"
        lines.append(f"| ({k}) {e['name']} | {100 * s['success']:.0f} % ({e['ok']}/{e['n']}; {100 * lo:.0f}–"
                     f"{100 * hi:.0f} %) | {s['falls']:.1f} | {e['drifts']:.1f} | {e['diverged']:.1f} | "
                     f"{s['mpjpe_mrad']:.1f} | {s['gmpjpe_mm']:.0f} | {gap_s} | {s['worlds']} | {s['iterations']} | "
                     f"{', '.join(map(str, s['seeds']))} |")
    if "a" in summary and "d" in summary and summary["d"]["gmpjpe_mm"] >= summary["a"]["gmpjpe_mm"]:
        lines.append("\nThe oracle (d) does not beat (a) on g-MPJPE: no gap ratio.")
    return lines + [""]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path, help="output folder (summary.json, table.md)")
    p.add_argument("--default", nargs="*", default=[], help="run folders of the default mismatch, one per seed")
    p.add_argument("--uneven", nargs="*", default=[], help="run folders of the uneven mismatch, one per seed")
    args = p.parse_args()
    summary, lines = {}, ["# Floor benchmark, per mismatch and policy (mean over seeds)\n"]
    for name, dirs in (("default", args.default), ("uneven", args.uneven)):
        if not dirs:
            continue
        missing = [d for d in dirs if not (Path(d) / "results.json").is_file()]
        if missing:
            raise SystemExit(f"no results.json in {', '.join(missing)}")
        runs = [json.loads((Path(d) / "results.json").read_text()) for d in dirs]
        summary[name], extra = summarise(runs)
        lines += table(name, summary[name], extra)
    if not summary:
        raise SystemExit("give run folders with --default and/or --uneven")
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
    (args.out / "table.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
