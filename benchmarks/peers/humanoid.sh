#!/usr/bin/env bash
# One leg of the humanoid fight (benchmarks/peers/humanoid.py) on one mismatch, from the repository root.
# Usage: bash benchmarks/peers/humanoid.sh MISMATCH LEG [FLAGS...]
#   MISMATCH  default: data/dataset.npz (shipped); uneven: recorded here by
#             `wresdyn collect --mismatch data/mismatch_uneven.toml` (deterministic) unless $UNEVEN exists
#   LEG       peer | wresdyn | report; FLAGS go to the leg (peer: --threads N --max-seconds S --resume;
#             wresdyn: --device cpu|cuda:0)
# Output: ${OUT:-benchmarks/results/peers/humanoid}/MISMATCH
set -euo pipefail
[ $# -ge 2 ] || { sed -n 2,8p "$0"; exit 2; }
M=$1; LEG=$2; shift 2
PY=${PYTHON:-python}
export OMP_NUM_THREADS=1
ROOT=${OUT:-benchmarks/results/peers/humanoid}
case $M in
  default) DATA=data/dataset.npz ;;
  uneven) DATA=${UNEVEN:-data/uneven/dataset.npz}
          [ -f "$DATA" ] || $PY -m wresdyn.cli collect --mismatch data/mismatch_uneven.toml --out "$(dirname "$DATA")" ;;
  *) echo "error: MISMATCH is default or uneven, not '$M'" >&2; exit 2 ;;
esac
if [ "$LEG" = report ]; then
  exec $PY benchmarks/peers/humanoid.py report --out "$ROOT/$M" --data "$DATA" --title "humanoid, $M mismatch" "$@"
fi
exec $PY benchmarks/peers/humanoid.py "$LEG" "$DATA" --out "$ROOT/$M" "$@"
