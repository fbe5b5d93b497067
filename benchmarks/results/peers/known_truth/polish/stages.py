"""Where the seconds of wresdyn's chosen known-truth recipes go: one identification to warm up, one timed, one under
cProfile (its cumulative seconds per stage, inflated by the profiler alike). Load average at the start printed.

    python benchmarks/results/peers/known_truth/polish/stages.py > benchmarks/results/peers/known_truth/polish/stages.txt
"""

import cProfile
import pstats
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[5]
sys.path[:0] = [str(ROOT), str(ROOT / "benchmarks" / "peers")]
import torch  # noqa: E402
import torch._dynamo  # noqa: E402,F401  as the benchmark: imported before the timers

import known_truth as kt  # noqa: E402
from wresdyn.identify.sysid import identify  # noqa: E402
from wresdyn.identify.sysid_config import SysIdConfig  # noqa: E402

STAGES = {"validation replays": ("selection.py", "__call__"), "Adam loop": ("window_fit.py", "run_window_fit"),
          "polish": ("refine.py", "polish"), "simulator builds": ("simulator.py", "__init__")}

torch.set_num_threads(1)
print(f"load average at start {open('/proc/loadavg').read().split()[:3]}")
for name, recipe in (("spring_mass", "wresdyn 1 step polish"), ("arm5_armature", "wresdyn 200 steps polish")):
    case = kt.CASES[name]
    robot, ds, _ = kt.dataset(case)
    cfg = SysIdConfig(fit=case.fit, identifiability=False, **kt.RECIPES[recipe])
    identify(robot, ds, cfg, log=lambda s: None)
    t0 = time.perf_counter()
    identify(robot, ds, cfg, log=lambda s: None)
    plain = time.perf_counter() - t0
    prof = cProfile.Profile()
    prof.enable()
    identify(robot, ds, cfg, log=lambda s: None)
    prof.disable()
    stats = pstats.Stats(prof).stats
    total = max(v[3] for k, v in stats.items() if k[2] == "identify")
    print(f"{name} ({recipe}): {plain:.2f} s timed, {total:.2f} s under cProfile, of which (nested: the Adam loop's "
          "and the polish's seconds hold their own validation replays)")
    for stage, key in STAGES.items():
        hits = [(v[1], v[3]) for k, v in stats.items() if (Path(k[0]).name, k[2]) == key]
        calls, cum = max(hits, key=lambda h: h[1]) if hits else (0, 0.0)  # the outermost of a name
        print(f"  {stage:20s} {cum:6.2f} s  ({calls} calls)")
