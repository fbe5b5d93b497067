#!/usr/bin/env bash
# The real-hardware benchmark (issue 13): the full SAGE SO-101 set (40 runs, ../shared/real/so101/), whole runs
# (each its own motion family) held out, PD-only vs the hybrid and identification, each started from a kp search
# (--gain-grid) and from the file's kp, the residual alone and identification with a delay search; then the
# baselines (LeRobot's MuJoCo model, a BAM-style drive) replayed in MuJoCo on the same runs; then the servo model.
# Raw output: benchmarks/results/so101/ and benchmarks/results/so101_servo/.
#   bash benchmarks/real/so101_real.sh SO101_TARBALL_DIR OUT_DIR
set -euo pipefail
src=${1:?usage: so101_real.sh DIR_WITH_so101-sage-logs.tar.xz OUT_DIR}
out=${2:?usage: so101_real.sh DIR OUT_DIR}
w=${WRESDYN:-.venv/bin/wresdyn}
py=${PYTHON:-.venv/bin/python}
mkdir -p "$out/logs" && tar -xJf "$src/so101-sage-logs.tar.xz" -C "$out/logs"
$w collect --robot scenes/so101/so101.xml --logs "$out/logs/logs" --map data/so101/map.toml \
    --assign 'pick_place=ood' --assign 'figure_eight=ood' --validation-fraction 0.15 --heldout-fraction 0.15 \
    --out "$out/data"
# kp factors for --gain-grid: the file's servo (kp 998 N*m/rad, saturating at 3.35 N*m) against softer ones
grid=1,0.5,0.2,0.1,0.05,0.02,0.01,0.005
$w fit "$out/data/dataset.npz" --gain-grid $grid --out "$out/hybrid_gain_grid" --eval
$w identify "$out/data/dataset.npz" --gain-grid $grid --out "$out/identify_gain_grid" --eval
$w fit "$out/data/dataset.npz" --out "$out/hybrid" --eval
$w fit "$out/data/dataset.npz" --model network --out "$out/network" --eval
$w identify "$out/data/dataset.npz" --delay-grid 0,10,25,40,55,70 --out "$out/identify_delay" --eval
$py benchmarks/real/so101_baselines.py "$out/data/dataset.npz" --json "$out/baselines.json" | tee "$out/baselines.txt"
# Servo drives (SERVO=0 skips them): benchmarks/real/so101_servo_real.sh on the same logs
if [[ ${SERVO:-1} != 0 ]]; then
  bash benchmarks/real/so101_servo_real.sh "$src" "$out"
fi
