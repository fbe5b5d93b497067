#!/usr/bin/env bash
# The peer benchmark on both mismatches, one after the other on the same cores (benchmarks/peer_sysid.py):
# the shipped dataset, then the uneven mismatch recorded by `wresdyn collect` (deterministic, ~20 s).
# Usage: bash benchmarks/peer_sysid.sh [OUT]  (default benchmarks/results/peer_sysid)
set -euo pipefail
OUT=${1:-benchmarks/results/peer_sysid}
PY=${PYTHON:-python}
export OMP_NUM_THREADS=1
UNEVEN=${UNEVEN:-data/uneven/dataset.npz}
[ -f "$UNEVEN" ] || $PY -m wresdyn.cli collect --mismatch data/mismatch_uneven.toml --out "$(dirname "$UNEVEN")"
ARGS=(--peer-budget "${BUDGET:-420}" --peer-horizon "${HORIZON:-250}" --peer-chunks "${CHUNKS:-1}")
$PY benchmarks/peer_sysid.py data/dataset.npz --out "$OUT/default" "${ARGS[@]}"
$PY benchmarks/peer_sysid.py "$UNEVEN" --out "$OUT/uneven" "${ARGS[@]}"
