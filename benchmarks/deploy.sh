#!/usr/bin/env bash
# The zero-shot skill deployment benchmark (issue 15), CPU configuration, as in the README:
#   bash benchmarks/deploy.sh OUT
# 1. the default mismatch (the shipped dataset), fits included, timed;
# 2. PPO seeds 1 and 2 on the same corrections (run-to-run spread of the policies);
# 3. the second mismatch (data/mismatch_uneven.toml): record it, then the same command and defaults.
# Each run writes OUT/<name>/report.md, results.json, tracking_heldout.png (and the USD animation).
set -euo pipefail
OUT=${1:?usage: bash benchmarks/deploy.sh OUT}
W=${WRESDYN:-.venv/bin/wresdyn}
mkdir -p "$OUT"
/usr/bin/time -v "$W" deploy --out "$OUT/default" 2>&1 | tee "$OUT/default.log"
for s in 1 2; do
  "$W" deploy --out "$OUT/seed$s" --seed "$s" --calibrated "$OUT/default/calibrated" \
    --delta "$OUT/default/delta_action" --no-animation 2>&1 | tee "$OUT/seed$s.log"
done
"$W" collect --mismatch data/mismatch_uneven.toml --out "$OUT/uneven_data" 2>&1 | tee "$OUT/uneven_collect.log"
/usr/bin/time -v "$W" deploy "$OUT/uneven_data/dataset.npz" --out "$OUT/uneven" 2>&1 | tee "$OUT/uneven.log"
