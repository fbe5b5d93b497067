"""job.sh's summary of the results folder given: per 2000-iteration run train_s, ms an iteration per window length and
the final validation against the plain path's; the plain path's rounding floor at each nudge point."""

import json
import sys
from pathlib import Path

PLAIN = 0.03141096408435372  # the plain path's final validation on earlier H200s [rad]
r = Path(sys.argv[1])
for n in ("tiles", "tiles2"):
    if not (r / f"{n}.json").exists():
        print(f"{n}: no result")
        continue
    x = json.loads((r / f"{n}.json").read_text())
    ms = ", ".join(f"H{p['horizon']} {p['ms_per_iteration']:.2f}" for p in x["per_length"])
    val = x["final_validation"]
    print(f"{n}: train_s {x['train_s']:.2f} (overhead {x['overhead_s']:.2f}); ms/iteration {ms}; final validation "
          f"{val!r} ({val - PLAIN:+.3e} rad against the plain path's {PLAIN})")
for f in sorted(r.glob("floor_plain_*.json")):
    x = json.loads(f.read_text())
    print(f"plain path nudged after iteration {x['at']}: control {x['control_final_validation']!r} rad "
          f"({x['control_final_validation'] - PLAIN:+.3e} against the uninterrupted {PLAIN}); "
          + "; ".join(f"nudge {y['nudge_seed']}: {y['distance_rad']:.3e}" for y in x["nudged"])
          + f"; largest {x['floor_rad']:.3e} rad")
