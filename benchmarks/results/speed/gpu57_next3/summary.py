"""job.sh's summary of the results folder given: the tests' last line, which MathDx modules came prebuilt, µs a step of
each block shape, and per 2000-iteration run train_s, ms an iteration per window length and the final validation."""

import json
import sys
from pathlib import Path

PLAIN = 0.03141096408435372  # the plain path's final validation on two earlier H200s [rad]
r = Path(sys.argv[1])


def lines(name: str) -> list:
    return (r / name).read_text().splitlines() if (r / name).exists() else []


tests = lines("tests.txt")
print("tests:", next((x for x in reversed(tests) if " passed" in x or " failed" in x or " error" in x), "no summary"))
checks = [x for x in lines("prebuilt.txt") if ": ok " in x or "MISMATCH" in x]
print(f"prebuilt index: {sum(': ok ' in x for x in checks)} of {len(checks)} entries match this host's hashes")
for half in ("ready_fwd.txt", "ready_bwd.txt"):
    got = [x for x in lines(half) if x.endswith(" s") and (": prebuilt " in x or ": cache or compile " in x)]
    secs = sum(float(x.split()[-2]) for x in got)
    print(f"{half}: {sum(': prebuilt ' in x for x in got)} of {len(got)} modules from the prebuilt folder, "
          f"{secs:.1f} s")
if (r / "step.json").exists():
    step = json.loads((r / "step.json").read_text())
    print(f"one step forward + backward, {step['device']}, {step['windows']} windows, H = {step['horizon']}:")
    for name, fig in [("torch fused", step["torch"])] + [
            ("{rows}x{chunk}x{threads}{m}".format(**t["block"], m="m" if t["block"]["mathdx"] else ""), t)
            for t in step["tiles"]]:
        if "error" in fig:
            print(f"  {name}: failed: {fig['error']}")
            continue
        graph = fig.get("graph_us_per_step")
        diff = max(fig.get("max_abs_diff", {0: 0.0}).values())
        print(f"  {name}: graph {graph if graph is None else round(graph, 1)} µs, eager "
              f"{fig['eager_us_per_step']:.1f} µs, first call {fig['first_call_s']:.1f} s, "
              f"max |tiles - torch| {diff:.1e}")
for n in ("fused", "tiles_m"):
    if not (r / f"{n}.json").exists():
        print(f"{n}: no result")
        continue
    x = json.loads((r / f"{n}.json").read_text())
    ms = ", ".join(f"H{p['horizon']} {p['ms_per_iteration']:.2f}" if p["ms_per_iteration"] is not None
                   else f"H{p['horizon']} -" for p in x["per_length"])
    val = x["final_validation"]
    apart = "-" if val is None else f"{val - PLAIN:+.3e}"
    print(f"{n}: block {x.get('tile_block', '-')}; train_s {x['train_s']:.2f}; ms/iteration {ms}; final validation "
          f"{val!r} ({apart} rad against the plain path's {PLAIN})")
