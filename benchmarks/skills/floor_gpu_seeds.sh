#!/usr/bin/env bash
# Several seeds of the full-size floor benchmark side by side on one GPU (each a `benchmarks/skills/floor_gpu.sh` run;
# 4096 worlds leave most of an H100/H200 idle, so seeds share it), corrections fitted on the stand on the CPU:
#   bash benchmarks/skills/floor_gpu_seeds.sh OUT CALIBRATED DELTA "0 1 2" [more deploy flags]
# Resumable like floor_gpu.sh: rerun the same command. Writes OUT/seedS/{report.md,results.json} and OUT/seedS.log.
set -euo pipefail
OUT=${1:?usage: bash benchmarks/skills/floor_gpu_seeds.sh OUT CALIBRATED DELTA "SEEDS" [flags]}
CAL=${2:?calibrated run}
DEL=${3:?delta-action run}
SEEDS=${4:?seeds, e.g. "0 1 2"}
shift 4
here=$(dirname "$0")
pids=()
for s in $SEEDS; do
  bash "$here/floor_gpu.sh" "$OUT/seed$s" "$CAL" "$DEL" --seed "$s" "$@" > /dev/null 2>&1 &
  pids+=($!)
done
status=0
for p in "${pids[@]}"; do wait "$p" || status=1; done
exit $status
