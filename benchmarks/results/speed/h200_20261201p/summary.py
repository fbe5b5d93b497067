"""job.sh's summary: per 2000-iteration run train_s, ms an iteration per window length, the final validation; the tests'
last line; the profile's kernel groups; the cold and warm fits' whole-command seconds."""

import json
import sys
from pathlib import Path

PLAIN = 0.03141096408435372  # the plain path's final validation on earlier H200s [rad]
r = Path(sys.argv[1])
for n in ("chain1", "loop1", "old1", "chain2", "loop2", "chain3", "plain", "chain4"):
    if not (r / f"{n}.json").exists():
        print(f"{n}: no result")
        continue
    x = json.loads((r / f"{n}.json").read_text())
    ms = ", ".join(f"H{p['horizon']} {p['ms_per_iteration']:.2f}" if p["ms_per_iteration"] is not None
                   else f"H{p['horizon']} -" for p in x["per_length"])
    val = x["final_validation"]
    apart = "-" if val is None else f"{val - PLAIN:+.3e}"
    over = "-" if x["overhead_s"] is None else f"{x['overhead_s']:.2f}"
    print(f"{n}: train_s {x['train_s']:.3f} (overhead {over}); ms/iteration {ms}; final validation "
          f"{val!r} ({apart} rad against the plain path's {PLAIN}); final loss {x['final_loss']!r}")
tests = (r / "tests.txt").read_text().splitlines() if (r / "tests.txt").exists() else []
print("tests:", next((x for x in reversed(tests) if " passed" in x or " failed" in x or " error" in x), "no summary"))
p = r / "profile_h64.json"
if p.exists():
    x = json.loads(p.read_text())
    kinds = ", ".join(f"{k} {v['count']} / {v['gpu_ms']:.3f} ms" for k, v in x["kernels"].items())
    total = sum(v["gpu_ms"] for v in x["kernels"].values())
    print(f"profile H = 64: graph {x['graph']['ms_per_iteration']:.3f} ms, eager {x['eager']['ms_per_iteration']:.3f} "
          f"ms an iteration; kernels {x['kernels_total']} with {total:.3f} ms GPU: {kinds}")
for c in ("coldfit_tiles",):
    s = r / c / "summary.txt"
    print(f"{c}:", s.read_text().strip() if s.exists() else "no result")
