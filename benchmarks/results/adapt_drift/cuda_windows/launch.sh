#!/bin/bash
# On a GPU machine, after the wheels' install.py, with PYTHONPATH exported by the caller: the online adapter with
# more windows per update on the GPU. The adjoint is the one kernel throughout (WRESDYN_ADJOINT_PIECES=0; compiled
# first by a short profile run), so every run takes the same arithmetic.
# 1. the excitation's validation timeline with windows = 8 (the default), 64 and 256, side by side;
# 2. the rule fixed before the runs: the windows with the lowest mean online error over the three drift phases
#    (friction doubled, payload, derate) among those whose no-drift worst second is <= 1.05x the fixed model
#    (ties: fewer windows);
# 3. the reported held-out timelines (the excitation and the skill motions) with the default and the chosen windows.
R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 WRESDYN_ADJOINT_PIECES=0 OMP_NUM_THREADS=1
B="python3 benchmarks/adapt/adapt_drift.py --oracles benchmarks/results/adapt_drift"
python3 benchmarks/speed/adapt_profile.py --device cuda > $R/warmup_profile.txt 2>&1
for w in 8 64 256; do
  $B --splits validation --seed 1 --set device=cuda windows=$w --out $R/validation_w$w > $R/validation_w$w.log 2>&1 &
done
wait
python3 - > $R/chosen.txt <<'PY'
import json, math
best = None
for w in (8, 64, 256):
    s = json.load(open(f"/root/res/validation_w{w}/summary.json"))
    err = sum(s["phases"][p]["online"] for p in ("friction", "payload", "derate")) / 3
    ok = s["no_drift_max_ratio"] is not None and s["no_drift_max_ratio"] <= 1.05
    print(f"windows {w}: drift phases' mean online error {err:.5f} rad, no-drift worst second {s['no_drift_max_ratio']}, "
          f"real-time factor {s['real_time_factor']:.2f}, eligible {ok}")
    if ok and (best is None or err < best[1] - 1e-12):
        best = (w, err)
print(f"chosen {best[0] if best else 8}")
PY
W=$(tail -1 $R/chosen.txt | cut -d' ' -f2)
for w in $(echo 8 $W | tr ' ' '\n' | sort -un); do
  $B --set device=cuda windows=$w --out $R/heldout_w$w > $R/heldout_w$w.log 2>&1 &
  $B --motion skill --splits heldout --set device=cuda windows=$w --out $R/skill_w$w > $R/skill_w$w.log 2>&1 &
done
wait
echo done > $R/DONE
