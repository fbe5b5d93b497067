#!/usr/bin/env bash
# The SO-101's servo model on the real SAGE runs: the runs imported with the STS3215 servo model (the same splits as
# benchmarks/real/so101_real.sh), identified from the servo priors without the goal profile, with the damper friction law
# at the rate and the effort-limit handling validation chose (docs/results/real-data.md), seeds 0 and 1 side by side
# (2 x 15-17 min on 2 cores); their ratios against the file's PD model. Raw output: benchmarks/results/so101_servo/.
#   bash benchmarks/real/so101_servo_real.sh SO101_TARBALL_DIR OUT_DIR
set -euo pipefail
src=${1:?usage: so101_servo_real.sh DIR_WITH_so101-sage-logs.tar.xz OUT_DIR}
out=${2:?usage: so101_servo_real.sh DIR OUT_DIR}
w=${WRESDYN:-.venv/bin/wresdyn}
py=${PYTHON:-.venv/bin/python}
if [[ ! -d "$out/logs/logs" ]]; then
  mkdir -p "$out/logs" && tar -xJf "$src/so101-sage-logs.tar.xz" -C "$out/logs"
fi
$w collect --robot scenes/so101/so101.xml --gains scenes/so101/servo.toml --logs "$out/logs/logs" \
    --map data/so101/map.toml --assign 'pick_place=ood' --assign 'figure_eight=ood' --validation-fraction 0.15 \
    --heldout-fraction 0.15 --out "$out/servo_data"
# backlash and encoder offsets: kept on validation, seed 0 (benchmarks/results/so101_servo/backlash/, 0.00511 ->
# 0.00502 rad; OOD 0.00824 -> 0.00885)
fields=kp,kd,armature,damping,friction,effort,bodies,deadband,noload_speed,startup_torque,stiction
fields=$fields,backlash,encoder_offset
pids=()
for s in 0 1; do
  OMP_NUM_THREADS=1 $w identify "$out/servo_data/dataset.npz" --gains scenes/so101/servo_no_profile.toml \
      --iterations 360 --select-every 90 --horizon-curriculum 16,32,64,128,256,512 --fit $fields \
      --friction-kappa 3e4 --effort-reset --seed $s --out "$out/servo_seed$s" --eval > "$out/servo_seed$s.log" 2>&1 &
  pids+=($!)
done
for p in "${pids[@]}"; do wait "$p"; done
PYTHONPATH=. $py benchmarks/real/so101_servo_ratios.py "$out/servo_seed0" "$out/servo_seed1" | tee "$out/servo_ratios.txt"
