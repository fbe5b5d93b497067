"""The rule of RULE.txt on the runs here: python benchmarks/results/adapt_drift/track_confirm/rule.py"""
import re
from pathlib import Path

import numpy as np

HERE = Path(__file__).parent
PHASES = ("friction", "payload", "derate")


def parse(run: Path):
    t = (run / "run.txt").read_text()
    m = re.search(r"no drift: online / fixed at most ([\d.]+) \(target <= 1.05\), mean ([\d.]+)", t)
    err = {k: float(v) for k, v in re.findall(r"^\s*(friction|payload|derate): fixed [\d.]+\s+online ([\d.]+)", t, re.M)}
    rec = {k: int(v) for k, v in re.findall(r"^\s*(\w+): online within 1.5x the oracle \(3 s mean\) after (\d+) s", t, re.M)}
    return float(m.group(1)), float(m.group(2)), np.mean([err[k] for k in PHASES]), rec


def table(name, runs):
    rows = [parse(r) for r in runs]
    bad = sum(r[0] > 1.05 for r in rows)
    drift = float(np.mean([r[2] for r in rows]))
    print(f"{name}: {len(rows)} runs; a no-drift second above 1.05x in {bad}; worst seconds "
          f"{[r[0] for r in rows]}; no-drift means {[r[1] for r in rows]}; drift-phase error {1e3 * drift:.3f} mrad; "
          f"back within 1.5x of the oracle after (friction, payload, derate) {[tuple(r[3][k] for k in PHASES) for r in rows]}")
    return bad, drift, rows


def main() -> None:
    v = HERE / "validation"
    exc_defaults = HERE.parent / "track_leave"
    a = table("policy, defaults", [v / f"policy_defaults_s{s}" for s in range(2, 12)])
    b = table("policy, track_confirm", [v / f"policy_track_confirm_s{s}" for s in range(2, 12)])
    c = table("excitation, defaults", [exc_defaults / f"exc_s{s}_tlf" for s in range(3)])
    d = table("excitation, track_confirm", [v / f"excitation_track_confirm_s{s}" for s in range(3)])
    one, two = b[0] < a[0], b[1] <= 1.1 * a[1]
    three = all(max(r[3][k] for k in PHASES) <= 10 for r in d[2]) and d[1] <= 1.1 * c[1]
    print(f"(1) fewer runs above 1.05x: {one}; (2) policy drift error {b[1] / a[1]:.3f}x the defaults': {two}; "
          f"(3) excitation back within 10 s in every run and drift error {d[1] / c[1]:.3f}x: {three}")
    print("track_confirm becomes the default" if one and two and three else "the default stays false")

    # reporting only, not part of the rule: the reported (held-out) policy timeline, the defaults, benchmark seed 0
    # (track_leave/heldout/policy) and seeds 1-6
    table("held-out policy timeline, defaults, seeds 0-6",
          [HERE.parent / "track_leave/heldout/policy", *(HERE / "heldout_seeds" / f"s{s}" for s in range(1, 7))])


if __name__ == "__main__":
    main()
