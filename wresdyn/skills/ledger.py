"""The held-out ledger: one JSON line each time a benchmark scores its held-out motions, so that a report can list
every configuration ever scored on them (a held-out set scored over and over while choices are made is a validation
set; the ledger shows how often it was looked at).

A line holds the time (UTC), a hash of the configuration (the benchmark's, the task's and PPO's fields and the
mismatch, without the seed and the devices, which do not make another configuration), those fields themselves, the
seed, the policies and each one's mean held-out figures.
"""

from __future__ import annotations

import hashlib
import json
import time
from pathlib import Path

__all__ = ["LEDGER", "config_hash", "record_heldout", "read_ledger", "ledger_table"]

LEDGER = "heldout_ledger.jsonl"
"""The ledger's file name in a benchmark's output folder."""
_NOT_CONFIG = ("seed", "device", "beside_devices", "torch_threads")
"""Fields left out of the hash: they change how a run is made or which draw it is, not what is compared."""


def _strip(d):
    if isinstance(d, dict):
        return {k: _strip(v) for k, v in d.items() if k not in _NOT_CONFIG}
    return d


def config_hash(config: dict) -> str:
    """A short hash [12 hex digits] of ``config`` (nested dicts of JSON values) without :data:`_NOT_CONFIG`."""
    text = json.dumps(_strip(config), sort_keys=True, default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:12]


def record_heldout(paths, config: dict, seed: int, figures: dict[str, dict], n_motions: int) -> dict:
    """Append one line to each ledger of ``paths`` (their folders made) and return it.

    Args:
        paths: Ledger files (``.jsonl``), e.g. the run's ``out / LEDGER`` and a repository-level one.
        config: The configuration scored: ``{"benchmark": ..., "task": ..., "ppo": ..., "mismatch": ...}``.
        seed: The run's seed.
        figures: Per policy (and ``reference``), its mean held-out figures (floats).
        n_motions: Held-out motions scored.
    """
    entry = {"time": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()), "config_hash": config_hash(config),
             "seed": int(seed), "heldout_motions": int(n_motions), "policies": list(figures),
             "figures": figures, "config": config}
    line = json.dumps(entry, sort_keys=True, default=str) + "\n"
    for p in dict.fromkeys(Path(p) for p in paths):
        p.parent.mkdir(parents=True, exist_ok=True)
        with open(p, "a") as f:
            f.write(line)
    return entry


def read_ledger(path) -> list[dict]:
    """The lines of a ledger (none where it does not exist)."""
    path = Path(path)
    if not path.exists():
        return []
    return [json.loads(x) for x in path.read_text().splitlines() if x.strip()]


def ledger_table(path) -> str:
    """Markdown: every configuration ever scored on the held-out motions of ``path``'s ledger, one row each, with how
    many times and at which seeds, the first and last time, and the last scoring's success per policy."""
    rows = {}
    for e in read_ledger(path):
        r = rows.setdefault(e["config_hash"], {"n": 0, "seeds": set(), "first": e["time"]})
        r["n"] += 1
        r["seeds"].add(e["seed"])
        r["last"], r["figures"] = e["time"], e["figures"]
    lines = [f"Every configuration scored on held-out motions ({path}):", "",
             "| config | times scored | seeds | first | last | last success per policy |", "|---|---|---|---|---|---|"]
    for h, r in rows.items():
        success = ", ".join(f"{p} {100 * f['success']:.0f} %" for p, f in r["figures"].items() if "success" in f)
        lines.append(f"| `{h}` | {r['n']} | {', '.join(map(str, sorted(r['seeds'])))} | {r['first']} | {r['last']} "
                     f"| {success or '-'} |")
    return "\n".join(lines) + "\n"
