"""The polish's settings on the uneven mismatch, validation only: each polishes the selected parameters of the
committed ``refine_all_shared_delay`` leg (``uneven/wresdyn_refine_all_shared_delay/physics.json``, what that recipe's
Adam stages and refinement give, to the printed digit, before a polish) and prints its validation error and, for the
record, how many (joint, field) pairs land within 10 % of the truth (not a selection criterion). Held-out and OOD are
not read.

    python benchmarks/results/peers/humanoid/recipe_search/polish/search.py [INDEX ...]   # data/uneven/dataset.npz
"""

import dataclasses
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[6]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks" / "peers")]
import torch  # noqa: E402

import humanoid as fight  # noqa: E402
from peer_adapter import param_errors  # noqa: E402
from recipe_search import recipe_config  # noqa: E402
from wresdyn.identify.refine import polish  # noqa: E402
from wresdyn.identify.sysid import PhysicsScore  # noqa: E402
from wresdyn.learn.window_fit import joint_weights  # noqa: E402
from wresdyn.robot.physical import PhysicalParams  # noqa: E402
from wresdyn.sim import TrajectoryBank  # noqa: E402

SETTINGS = [{}, {"polish_threshold": 0.0}, {"polish_threshold": 100.0}, {"polish_windows": 64},
            {"polish_threshold": 0.0, "polish_windows": 64}, {"polish_threshold": 0.1}]
"""Over ``refine_all_shared_delay_polish`` (threshold 1, 16 windows, up to 20 steps)."""

torch.set_num_threads(1)
ds, robot, truth = fight.load(str(ROOT / "data" / "uneven" / "dataset.npz"))
LEG = ROOT / "benchmarks" / "results" / "peers" / "humanoid" / "uneven" / "wresdyn_refine_all_shared_delay"
start = PhysicalParams.load(LEG / "physics.json", robot)
score = PhysicsScore(robot, ds.split("validation"), ds.rate_hz, "auto", "cpu", weights=ds.fit_weights())
within = param_errors(start, truth, ds.split("train"))["within_10pct"]
print(f"start: validation {score(start):.6f}, within 10 % {within}", flush=True)
for i in [int(a) for a in sys.argv[1:]] or range(len(SETTINGS)):
    cfg = dataclasses.replace(recipe_config("refine_all_shared_delay_polish"), **SETTINGS[i])
    bank = TrajectoryBank(ds.split("train"), "cpu")
    t0 = time.perf_counter()
    out = polish(cfg, robot, bank, 1.0 / ds.rate_hz, start, score, joint_weights(ds, "cpu"), [], lambda s: None)
    v, within = score(out), param_errors(out, truth, ds.split("train"))["within_10pct"]
    print(f"{i} {SETTINGS[i]}: validation {v:.6f}, within 10 % {within}, {time.perf_counter() - t0:.0f} s", flush=True)
