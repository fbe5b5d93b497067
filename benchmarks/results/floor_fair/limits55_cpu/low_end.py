"""The calibrated robot at the low end of the effort range ``Randomization.effort_from_data`` gives (f): each limit the
option draws from the data set to the torque the training data demand of it (the recomputed report's
``demanded_effort_nm``), the others as identified. For a CPU preview of the option's stressful end
(``floor_kick_gap.py --sim``); the truth is not read.

    python benchmarks/results/floor_fair/limits55_cpu/low_end.py CALIBRATED REPORT OUT
"""

import json
import shutil
import sys
from pathlib import Path

cal, report, out = Path(sys.argv[1]), json.loads(Path(sys.argv[2]).read_text()), Path(sys.argv[3])
out.mkdir(parents=True, exist_ok=True)
for f in ("config.json", "residual.json", "policy.pt"):
    shutil.copy(cal / f, out / f)
d = json.loads((cal / "physics.json").read_text())
low = {n: x for n, x in report["demanded_effort_nm"].items()
       if report["effort_saturated"][n] < report["effort_saturated_min"]}
for n, x in low.items():
    j = d["joint_names"].index(n)
    print(f"{n}: {d['effort'][j]:.2f} -> {min(x, d['effort'][j]):.2f} N·m")
    d["effort"][j] = min(x, d["effort"][j])
(out / "physics.json").write_text(json.dumps(d))
