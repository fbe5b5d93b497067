#!/usr/bin/env bash
# The zero-shot skill benchmark (wresdyn deploy), CPU configuration, on the stand or on the floor (the task's two
# configurations), as in the README:
#   bash benchmarks/skills/deploy.sh OUT            # on the stand
#   bash benchmarks/skills/deploy.sh OUT --floor    # on the floor (wresdyn deploy --floor)
# 1. the default mismatch (the shipped dataset), fits included (on the stand in either case), timed;
# 2. PPO seeds 1 and 2 on the same corrections (run-to-run spread of the policies);
# 3. the second mismatch (data/mismatch_uneven.toml): record it, then the same command and defaults. For the floor the
#    recording adds the saturation probe: the uneven robot's worn knees are otherwise never driven into their limit.
# Each run writes OUT/<name>/report.md, results.json, tracking_heldout.png (and the USD animation).
set -euo pipefail
OUT=${1:?usage: bash benchmarks/skills/deploy.sh OUT [--floor]}
TASK=()
PROBE=()
if [ "${2:-}" = "--floor" ]; then
  # the real robot of the default mismatch is its file's: the dataset's header keeps the nominal floor
  TASK=(--floor --mismatch data/mismatch_default.toml)
  PROBE=(--probe-saturation 6)
elif [ -n "${2:-}" ]; then
  echo "usage: bash benchmarks/skills/deploy.sh OUT [--floor]" >&2
  exit 2
fi
W=${WRESDYN:-.venv/bin/wresdyn}
mkdir -p "$OUT"
/usr/bin/time -v "$W" deploy "${TASK[@]}" --out "$OUT/default" 2>&1 | tee "$OUT/default.log"
for s in 1 2; do
  "$W" deploy "${TASK[@]}" --out "$OUT/seed$s" --seed "$s" --calibrated "$OUT/default/calibrated" \
    --delta "$OUT/default/delta_action" --no-animation 2>&1 | tee "$OUT/seed$s.log"
done
"$W" collect --mismatch data/mismatch_uneven.toml "${PROBE[@]}" --out "$OUT/uneven_data" 2>&1 | tee "$OUT/uneven_collect.log"
/usr/bin/time -v "$W" deploy "$OUT/uneven_data/dataset.npz" "${TASK[@]:0:1}" --out "$OUT/uneven" 2>&1 | tee "$OUT/uneven.log"
