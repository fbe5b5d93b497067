"""Gather every fight's own summary into ``benchmarks/results/peers/summary.json``: per fight, per tool, exactly
``heldout_error``, ``ood_error`` (mean |Δq| [rad, or m on a slider] of open-loop replays of whole trajectories),
``seconds_to_final``, ``converged`` (``{"value": bool, "reason": str}``), ``samples_used`` and ``machine``. A fight
whose run is missing is listed under ``not_run`` with what stops it, never as a number.

    python benchmarks/peers/summary.py        # after the fights' commands (benchmarks/README.md, peers)
"""

from __future__ import annotations

import json
from pathlib import Path

RESULTS = Path(__file__).resolve().parents[1] / "results" / "peers"
FIELDS = ("heldout_error", "ood_error", "seconds_to_final", "converged", "samples_used", "machine")


def converged(entry: dict) -> dict:
    """The fights record convergence as a bool with a ``stop`` line, or already as ``{"value", "reason"}``."""
    c = entry["converged"]
    if isinstance(c, dict):
        return {"value": bool(c["value"]), "reason": str(c["reason"])}
    return {"value": bool(c), "reason": str(entry.get("stop", ""))}


def row(entry: dict) -> dict:
    out = {k: entry[k] for k in FIELDS}
    out["converged"] = converged(entry)
    return out


def humanoid(fights: dict, not_run: dict) -> None:
    for mismatch in ("default", "uneven"):
        f = RESULTS / "humanoid" / mismatch / "summary.json"
        if not f.exists():
            not_run[f"humanoid_{mismatch}"] = "not run: see docs/results/peers.md (what the run needs)"
            continue
        tools = json.loads(f.read_text())
        fights[f"humanoid_{mismatch}"] = {name: row(t) for name, t in tools.items() if name != "extra"}


def so101(fights: dict) -> None:
    d = json.loads((RESULTS / "so101" / "summary.json").read_text())
    for name, tools in d["fights"].items():
        fights[f"so101_{name.split('_', 1)[1]}"] = {tool: row(t) for tool, t in tools.items()}


def known_truth(fights: dict) -> None:
    """The first run (``known_truth/``) and the runs with the polish's recipes (``known_truth/polish/``, on shared
    cores, and ``known_truth/polish_idle/``, the same on an idle machine), which timed the peer and wresdyn's defaults
    again beside them."""
    runs = (("", "known_truth"), ("polish", "known_truth_polish"), ("polish_idle", "known_truth_polish_idle"))
    for run, key in runs:
        d = json.loads((RESULTS / "known_truth" / run / "summary.json").read_text())
        for case, c in d["cases"].items():
            fights[f"{key}_{case}"] = {tool: row(t) for tool, t in c["tools"].items()}


def main() -> None:
    fights: dict = {}
    not_run: dict = {
        "isaac_sim_humanoid": "Isaac Sim 6.2's backend runs outside Kit (benchmarks/results/peers/isaac_sim/), but "
                              "its recipe has no comparable score: CPU smoke runs fitted 1-2 of its 60 iterations on "
                              "short chunks; on one H200 shared with three PPO trainings (isaac_sim/h200_20261130/) "
                              "the full-data solve ran 1277 s without finishing its first iteration (its progress "
                              "never passed the first of 16 training chunks), so its 60 iterations would need more "
                              "than 60 x 21 min on this path (a lower bound), far beyond a 30-minute GPU session; "
                              "neither the peer nor the adapter resumes a solve across sessions"}
    humanoid(fights, not_run)
    so101(fights)
    known_truth(fights)
    out = RESULTS / "summary.json"
    out.write_text(json.dumps({"fights": fights, "not_run": not_run}, indent=1) + "\n")
    for name, tools in fights.items():
        for tool, r in tools.items():
            print(f"{name:34s} {tool:40s} held-out {r['heldout_error']:.3g}  OOD {r['ood_error'] if r['ood_error'] is None else format(r['ood_error'], '.3g')}"
                  f"  {r['seconds_to_final']:.0f} s  converged {r['converged']['value']}")
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
