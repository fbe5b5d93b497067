#!/usr/bin/env bash
# Skills on the floor at full size on one GPU (wresdyn deploy --floor --full), corrections fitted on the stand on
# the CPU and carried (the CPU run of `benchmarks/skills/deploy.sh OUT --floor` writes them into OUT/default/{calibrated,delta_action}):
#   bash benchmarks/skills/floor_gpu.sh RUN CALIBRATED DELTA [more deploy flags]
# On a host of several GPUs, CUDA_VISIBLE_DEVICES=0,1 and `--beside-devices cuda:1` fine-tune (c) on the second
# beside (b) on the first. Resumable: rerun the same command to go on from the last checkpoints. Writes
# RUN/report.md, RUN/results.json and appends the output to RUN.log.
set -euo pipefail
RUN=${1:?usage: bash benchmarks/skills/floor_gpu.sh RUN CALIBRATED DELTA [flags]}
CAL=${2:?calibrated run}
DEL=${3:?delta-action run}
shift 3
PY=${PYTHON:-python3}
mkdir -p "$(dirname "$RUN")"
start=$(date +%s)
PYTHONUNBUFFERED=1 "$PY" -m wresdyn.cli deploy --floor --full --device cuda:0 --calibrated "$CAL" --delta "$DEL" \
  --out "$RUN" "$@" 2>&1 | tee -a "$RUN.log"
echo "wall-clock of this call: $(( $(date +%s) - start )) s" | tee -a "$RUN.log"
