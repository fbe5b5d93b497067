"""Two configurations of the floor benchmark side by side on validation: success per policy and motion family.

    python benchmarks/skills/floor_fair_compare.py RUN_A... -- RUN_B... [--names NAME_A NAME_B]

Each ``RUN`` is a ``wresdyn deploy --floor`` output folder (its ``results.json``), one a seed; the runs before ``--``
are configuration A, those after it B (e.g. ``floor_unvp_s*`` against ``floor_unvp55_s*``). Prints a Markdown table:
for each policy its real-robot success on the validation motions, all of them and per family (the family is the motion's
name between ``validation_`` and its index), as the mean over seeds of each seed's rate, A -> B. Validation only:
the figures a choice between configurations may be made on; held-out motions are for the reported configuration.
"""

from __future__ import annotations

import argparse
import json
import re
import sys
from pathlib import Path

ALL = "all"
"""The column of every validation motion together."""


def family(motion: str) -> str:
    """The motion family of a validation motion's name (``validation_weight_shift_3`` -> ``weight_shift``)."""
    m = re.fullmatch(r"validation_(.+)_\d+", motion)
    if m is None:
        raise ValueError(f"{motion!r} is not a validation motion's name")
    return m.group(1)


def success(run: Path) -> dict[str, dict[str, float]]:
    """One run's validation success rate (0-1) per policy and family (and :data:`ALL`), on the real robot."""
    validation = json.loads((Path(run) / "results.json").read_text())["real"]["validation"]
    out = {}
    for policy, r in validation.items():
        groups: dict[str, list[float]] = {}
        for m in r["motions"]:
            groups.setdefault(family(m["motion"]), []).append(float(m["success"]))
        out[policy] = {ALL: float(r["mean"]["success"]), **{f: sum(v) / len(v) for f, v in groups.items()}}
    return out


def mean_over_seeds(runs: list[Path]) -> dict[str, dict[str, float]]:
    """:func:`success` averaged over the runs (seeds), for the policies and families every run has."""
    each = [success(r) for r in runs]
    policies = [p for p in each[0] if all(p in e for e in each)]
    return {p: {f: sum(e[p][f] for e in each) / len(each) for f in each[0][p] if all(f in e[p] for e in each)}
            for p in policies}


def table(a: dict, b: dict, names: tuple[str, str]) -> str:
    """The Markdown table of :func:`mean_over_seeds` of A and B, in %, ``A -> B`` per cell."""
    policies = [p for p in a if p in b]
    families = [f for f in a[policies[0]] if f in b[policies[0]]]
    lines = [f"Validation success on the real robot, mean over seeds, {names[0]} -> {names[1]}:", "",
             "| policy | " + " | ".join(families) + " |", "|---" * (len(families) + 1) + "|"]
    for p in policies:
        cells = [f"{100 * a[p][f]:.1f} -> {100 * b[p][f]:.1f}" for f in families]
        lines.append(f"| {p} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> str:
    argv = sys.argv[1:] if argv is None else argv
    if "--" not in argv:
        sys.exit(__doc__)
    cut = argv.index("--")
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("runs", nargs="+", type=Path, help="RUN_B... (RUN_A... come before --)")
    parser.add_argument("--names", nargs=2, default=("A", "B"), help="the two configurations' names in the table")
    args = parser.parse_args(argv[cut + 1:])
    if not argv[:cut]:
        parser.error("configuration A needs at least one run before --")
    text = table(mean_over_seeds([Path(r) for r in argv[:cut]]), mean_over_seeds(args.runs), tuple(args.names))
    print(text, end="")
    return text


if __name__ == "__main__":
    main()
