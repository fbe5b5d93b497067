"""The rule of RULE.txt on the runs here: python benchmarks/results/adapt_drift/detect_norm/rule.py"""
import sys
from pathlib import Path

HERE = Path(__file__).parent
sys.path.insert(0, str(HERE.parent / "track_confirm"))
from rule import PHASES, table  # noqa: E402  (the same parsing of run.txt)

v = HERE / "validation"
defaults = HERE.parent / "track_confirm" / "validation"
exc_defaults = HERE.parent / "track_leave"
a = table("policy, defaults", [defaults / f"policy_defaults_s{s}" for s in range(2, 12)])
c = table("excitation, defaults", [exc_defaults / f"exc_s{s}_tlf" for s in range(3)])
best = None
for f in ("1.75", "2.0", "2.25"):
    b = table(f"policy, command, factor {f}", [v / f"f{f}_pol_s{s}" for s in range(2, 12)])
    d = table(f"excitation, command, factor {f}", [v / f"f{f}_exc_s{s}" for s in range(3)])
    one, two = b[0] < a[0], b[1] <= 1.05 * a[1]
    three = all(max(r[3][k] for k in PHASES) <= 10 for r in d[2]) and d[1] <= 1.05 * c[1]
    print(f"factor {f}: (1) {b[0]} runs above 1.05x against {a[0]}: {one}; (2) policy drift error {b[1] / a[1]:.3f}x: {two}; "
          f"(3) excitation back within 10 s in every run and drift error {d[1] / c[1]:.3f}x: {three}")
    if one and two and three:
        key = (b[0], (b[1] + d[1]) / 2)
        best = min(best, (key, f)) if best else (key, f)
print(f"detect_norm = command, detect_factor = {best[1]} becomes the default" if best else "detect_norm stays none")
