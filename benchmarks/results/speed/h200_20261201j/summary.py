"""job.sh's summary of the results folder given: the tests' last line, µs a step of each path, and per 2000-iteration
run train_s, ms an iteration per window length and the final validation against the plain path's."""

import json
import sys
from pathlib import Path

PLAIN = 0.03141096408435372  # the plain path's final validation on earlier H200s [rad]
r = Path(sys.argv[1])
tests = (r / "tests.txt").read_text().splitlines() if (r / "tests.txt").exists() else []
print("tests:", next((x for x in reversed(tests) if " passed" in x or " failed" in x or " error" in x), "no summary"))
if (r / "step.json").exists():
    step = json.loads((r / "step.json").read_text())
    print(f"one step forward + backward, {step['device']}, {step['windows']} windows, H = {step['horizon']}:")
    rows = [("torch fused", step["torch"])] + [("tiles {rows}x{chunk}x{threads}".format(**t["block"]), t)
                                               for t in step["tiles"]]

    for name, fig in rows:
        if "error" in fig:
            print(f"  {name}: failed: {fig['error']}")
            continue
        diff = max(fig.get("max_abs_diff", {0: 0.0}).values())
        print(f"  {name}: graph {fig.get('graph_us_per_step', float('nan')):.1f} µs, eager "
              f"{fig['eager_us_per_step']:.1f} µs, first call {fig['first_call_s']:.1f} s, max |diff| {diff:.1e}")
for n in ("tiles", "fused", "tiles2", "plain"):  # the 2000-iteration runs of h200_20261201i, j and k
    if not (r / f"{n}.json").exists():
        print(f"{n}: no result")
        continue
    x = json.loads((r / f"{n}.json").read_text())
    ms = ", ".join(f"H{p['horizon']} {p['ms_per_iteration']:.2f}" if p["ms_per_iteration"] is not None
                   else f"H{p['horizon']} -" for p in x["per_length"])
    val = x["final_validation"]
    apart = "-" if val is None else f"{val - PLAIN:+.3e}"
    print(f"{n}: train_s {x['train_s']:.2f}; ms/iteration {ms}; final validation {val!r} ({apart} rad against the "
          f"plain path's {PLAIN})")
