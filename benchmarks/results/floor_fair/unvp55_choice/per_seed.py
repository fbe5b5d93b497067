"""Per seed and configuration, (b)'s and (f)'s real-robot figures on one split, and successes per motion family.

    python benchmarks/results/floor_fair/unvp55_choice/per_seed.py SPLIT RUN...

SPLIT is ``validation`` or ``heldout``; each ``RUN`` a ``wresdyn deploy --floor`` folder (its ``results.json``).
Prints one Markdown row per run and policy: success, falls, MPJPE [mrad], g-MPJPE [mm] (the run's means over the
split's motions) and the count of successful motions per family (the name between the split and the index).
"""

import json
import sys
from pathlib import Path

POLICIES = ("b_calibrated", "f_calibrated_narrow")
"""The policies the effort line search's corrections retrained; (a), (c), (d), (e) are the same in both."""


def rows(split: str, run: Path) -> list[str]:
    real = json.loads((run / "results.json").read_text())["real"][split]
    out = []
    for policy in POLICIES:
        m, fam = real[policy]["mean"], {}
        for motion in real[policy]["motions"]:
            name = motion["motion"].removeprefix(f"{split}_").rsplit("_", 1)[0]
            ok, n = fam.get(name, (0, 0))
            fam[name] = (ok + round(motion["success"]), n + 1)
        families = ", ".join(f"{k} {ok}/{n}" for k, (ok, n) in fam.items())
        out.append(f"| {run.name} | {policy} | {100 * m['success']:.1f} % | {m['falls']} | {1e3 * m['mpjpe']:.1f} | "
                   f"{1e3 * m['g_mpjpe']:.1f} | {families} |")
    return out


def main() -> None:
    split, runs = sys.argv[1], [Path(r) for r in sys.argv[2:]]
    print(f"| run | policy | {split} success | falls | MPJPE [mrad] | g-MPJPE [mm] | successes per family |")
    print("|---|---|---|---|---|---|---|")
    for run in runs:
        print("\n".join(rows(split, run)))


if __name__ == "__main__":
    main()
