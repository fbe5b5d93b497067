"""job.sh's summary of the results folder given: per 2000-iteration run train_s, ms an iteration per window length and
the final validation against the plain path's; the plain path's rounding floor; the tests' last line; the profiles'
kernel groups."""

import json
import sys
from pathlib import Path

PLAIN = 0.03141096408435372  # the plain path's final validation on earlier H200s [rad]
r = Path(sys.argv[1])
for n in ("tiles", "old_tiles", "tiles2", "old_tiles2", "eager"):
    if not (r / f"{n}.json").exists():
        print(f"{n}: no result")
        continue
    x = json.loads((r / f"{n}.json").read_text())
    ms = ", ".join(f"H{p['horizon']} {p['ms_per_iteration']:.2f}" if p["ms_per_iteration"] is not None
                   else f"H{p['horizon']} -" for p in x["per_length"])
    val = x["final_validation"]
    apart = "-" if val is None else f"{val - PLAIN:+.3e}"
    over = "-" if x["overhead_s"] is None else f"{x['overhead_s']:.2f}"
    print(f"{n}: train_s {x['train_s']:.2f} (overhead {over}); ms/iteration {ms}; final validation "
          f"{val!r} ({apart} rad against the plain path's {PLAIN})")
if (r / "floor_plain.json").exists():
    f = json.loads((r / "floor_plain.json").read_text())
    print(f"plain path resumed untouched after iteration {f['at']}: {f['control_final_validation']!r} rad "
          f"({f['control_final_validation'] - PLAIN:+.3e} against the uninterrupted {PLAIN})")
    for x in f["nudged"]:
        print(f"  nudge {x['nudge_seed']}: {x['final_validation']!r} rad, {x['distance_rad']:.3e} from the control")
    print(f"  largest: {f['floor_rad']:.3e} rad")
else:
    print("floor: no result")
if (r / "paths.txt").exists():
    print((r / "paths.txt").read_text().strip())
tests = (r / "tests.txt").read_text().splitlines() if (r / "tests.txt").exists() else []
print("tests:", next((x for x in reversed(tests) if " passed" in x or " failed" in x or " error" in x), "no summary"))
for h in (64,):
    p = r / f"profile_h{h}.json"
    if not p.exists():
        print(f"profile H = {h}: no result")
        continue
    x = json.loads(p.read_text())
    kinds = ", ".join(f"{k} {v['count']} / {v['gpu_ms']:.3f} ms" for k, v in x["kernels"].items())
    total = sum(v["gpu_ms"] for v in x["kernels"].values())
    print(f"profile H = {h}: graph {x['graph']['ms_per_iteration']:.3f} ms, eager {x['eager']['ms_per_iteration']:.3f} "
          f"ms an iteration; kernels {x['kernels_total']} with {total:.3f} ms GPU: {kinds}")
