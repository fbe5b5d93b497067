"""The calibrated robot at the far end of (e)'s wide ranges, for a CPU preview of fix 1 (``DIAGNOSIS.md``): the
torso's mass ×1.2 (``Randomization.mass_scale``'s upper end) and its CoM moved by (e)'s half-ranges forward and up,
(+0.025, 0, +0.05) m (``com_offset``), written as ``cal_wide_torso``; the same with every effort limit ×0.9
(``effort_scale``'s lower end) as ``cal_wide_torso_effort``; and the far end of ``DIAGNOSIS.md``'s candidate 1 (the
torso's mass ×1.4, its CoM +(0.05, 0, 0.05) m, every effort limit ×0.8) as ``cal_cand1_end``. Directions are those of
the runs' kick losses; the truth is not read.

    python benchmarks/results/floor_fair/kick55/range_ends.py CALIBRATED OUT
"""

import json
import shutil
import sys
from pathlib import Path

import numpy as np

from wresdyn.skills.randomize import Randomization

cal, out = Path(sys.argv[1]), Path(sys.argv[2])
wide = Randomization()
ends = {"cal_wide_torso": (wide.mass_scale[1], wide.com_offset[0], wide.com_offset[2], 1.0),
        "cal_wide_torso_effort": (wide.mass_scale[1], wide.com_offset[0], wide.com_offset[2], wide.effort_scale[0]),
        "cal_cand1_end": (1.4, 0.05, 0.05, 0.8)}
for name, (up, dx, dz, effort) in ends.items():
    dst = out / name
    dst.mkdir(parents=True, exist_ok=True)
    for f in ("config.json", "residual.json", "policy.pt"):
        shutil.copy(cal / f, dst / f)
    d = json.loads((cal / "physics.json").read_text())
    b = d["body_names"].index(wide.com_body)
    d["body_mass"][b] *= up
    d["body_inertia"][b] = (np.asarray(d["body_inertia"][b]) * up).tolist()
    d["body_com"][b] = (np.asarray(d["body_com"][b]) + [dx, 0.0, dz]).tolist()
    d["effort"] = (np.asarray(d["effort"], float) * effort).tolist()
    (dst / "physics.json").write_text(json.dumps(d))
    print(f"{dst}: {wide.com_body} {d['body_mass'][b]:.2f} kg at {np.round(d['body_com'][b], 3)} m, "
          f"effort limits ×{effort:g}")
