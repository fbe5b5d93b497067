"""Screening harness: cache the drift benchmark's stream, run the adapter on its first S seconds, score the
no-drift seconds (online / fixed on the next second) as adapt_drift.py does, and print each update with --diag.

Paths as run (outside the repository): the checkout /work/wt33, the stream cache /work/fl/a33b/stream_<motion>.npz
(written by the first run: the validation split, seed 1, as ``adapt_drift.py --splits validation --seed 1``), the
policy /work/fl/pol/b_calibrated."""
import argparse, json, sys, time
from pathlib import Path
import numpy as np
sys.path.insert(0, "/work/wt33/benchmarks")
import adapt_drift as ad

ap = argparse.ArgumentParser()
ap.add_argument("--motion", default="policy")
ap.add_argument("--seconds", type=float, default=21)
ap.add_argument("--set", nargs="*", default=[])
ap.add_argument("--diag", action="store_true")
args = ap.parse_args()
import torch
torch.set_num_threads(1)
from wresdyn.adapt.adapter import Adapter, AdaptConfig
from wresdyn.data.loading import load_data
from wresdyn.sim.physics import PhysicalParams
ROOT = Path("/work/wt33")
ds, robot = load_data(str(ROOT / "data" / "dataset.npz"))
rate = ds.rate_hz
calib = PhysicalParams.load(ROOT / "benchmarks/results/grey_box/soft_friction/physics.json", robot)
cache = Path(f"/work/fl/a33b/stream_{args.motion}.npz")
if not cache.exists():
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.paths import DEFAULT_MISMATCH
    real = RealRobot(robot, Mismatch.load(DEFAULT_MISMATCH), rate)
    drift = ad.Drift(real, robot, ad.phases(160.0), rate)
    if args.motion == "policy":
        from adapt_drift_policy import policy_stream
        ref_q, ref_feet, _ = ad.skill_reference(robot, int(round(160 * rate)) + 1, rate, "validation", 1)
        run = policy_stream("/work/fl/pol/b_calibrated", real, drift, ref_q, ref_feet, rate, 1)
        q, qd, q_cmd = run.q, run.qd, run.q_cmd
    else:
        q_cmd = ad.commands(ds, 160.0, rate, splits=("validation",))
        q, qd, _ = real.record(q_cmd, np.random.default_rng(1), on_sample=drift)
    np.savez(cache, q=q, qd=qd, q_cmd=q_cmd)
z = np.load(cache)
q, qd, q_cmd = z["q"], z["qd"], z["q_cmd"]
n = int(args.seconds * rate) + 1
t = np.arange(len(q)) / rate
over = {k: ad._value(getattr(AdaptConfig(), k), v) for k, v in (s.split("=") for s in args.set)}
cfg = AdaptConfig(**over)
adapter = Adapter(robot, calib, rate, cfg)
held = {}
t0 = time.perf_counter()
for s0 in range(0, n, int(rate / 10)):
    s1 = min(s0 + int(rate / 10), n)
    for u in adapter.push(t[s0:s1], q[s0:s1], qd[s0:s1], q_cmd[s0:s1]):
        if args.diag:
            v = "acc" if u.accepted else "rej"
            print(f"t {u.t:6.2f} {v} before {u.open_loop_before:.5f} cand {u.open_loop_candidate:.5f} after "
                  f"{u.open_loop:.5f} fixed {u.open_loop_start:.5f} jump {u.jump:.2f} trk {int(u.tracking)} "
                  f"grid {u.effort_tried} {u.effort_set}")
    if s1 % int(rate) == 0:
        held[s1 // int(rate)] = adapter.physics
secs = [s for s in range(1, int(args.seconds)) if s < 20]
segs = [tuple(a[s * int(rate):(s + 1) * int(rate) + 1] for a in (q, qd, q_cmd)) for s in secs]
fx = ad.score(robot, segs, [calib] * len(secs), rate)
on = ad.score(robot, segs, [held.get(s, calib) for s in secs], rate)
r = on / fx
print("ratios", " ".join(f"{s}:{x:.3f}" for s, x in zip(secs, r)))
print(f"RESULT {' '.join(args.set) or 'defaults'}: max {r.max():.3f} mean {r.mean():.3f} accepted "
      f"{sum(u.accepted for u in adapter.updates)} tracking {sum(u.tracking for u in adapter.updates)} "
      f"grid_set {[f'{u.t:g}:{u.effort_set}' for u in adapter.updates if u.effort_set]} ({time.perf_counter()-t0:.0f} s)")
