#!/usr/bin/env bash
# Skills on the floor (wresdyn deploy --floor), CPU configuration:
#   bash benchmarks/floor.sh OUT
# 1. the default mismatch (the shipped dataset), corrections fitted on the stand, timed;
# 2. PPO seeds 1 and 2 on the same corrections;
# 3. the uneven mismatch (data/mismatch_uneven.toml): record it on the stand with the saturation probe (its worn knees
#    are otherwise never driven into their limit), then the same command and defaults.
# Each run writes OUT/<name>/report.md, results.json, tracking_heldout.png (and the USD animation).
set -euo pipefail
OUT=${1:?usage: bash benchmarks/floor.sh OUT}
W=${WRESDYN:-.venv/bin/wresdyn}
mkdir -p "$OUT"
/usr/bin/time -v "$W" deploy --floor --out "$OUT/default" 2>&1 | tee "$OUT/default.log"
for s in 1 2; do
  "$W" deploy --floor --out "$OUT/seed$s" --seed "$s" --calibrated "$OUT/default/calibrated" \
    --delta "$OUT/default/delta_action" --no-animation 2>&1 | tee "$OUT/seed$s.log"
done
"$W" collect --mismatch data/mismatch_uneven.toml --probe-saturation 6 --out "$OUT/uneven_data" 2>&1 | tee "$OUT/uneven_collect.log"
/usr/bin/time -v "$W" deploy "$OUT/uneven_data/dataset.npz" --floor --out "$OUT/uneven" 2>&1 | tee "$OUT/uneven.log"
