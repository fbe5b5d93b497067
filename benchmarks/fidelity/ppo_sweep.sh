#!/usr/bin/env bash
# PPO hyper-parameter sweep on a GPU host: one `wresdyn train` per line of a sweep file, spread round-robin
# over the GPUs, all at once, each under a wall-clock limit. Run it again with more iterations to extend the
# runs (they resume from their checkpoints); finished runs are evaluated and summarised, sorted by the
# validation error (choices are made on validation; held-out and OOD are printed for reporting only).
#
#   bash benchmarks/fidelity/ppo_sweep.sh SWEEP_FILE OUT_DIR ITERATIONS [LIMIT_S]
#
# SWEEP_FILE: one run per line, `NAME ARGS...`, ARGS passed to `wresdyn train` (e.g. --set ppo.desired_kl=0.06);
# blank lines and lines starting with # are skipped. Environment: GPUS (number of GPUs, default 1; 0 runs on
# the CPU), WRESDYN (the CLI, default `wresdyn`), WRESDYN_DATA (default data/dataset.npz).
set -uo pipefail
sweep=${1:?usage: ppo_sweep.sh SWEEP_FILE OUT_DIR ITERATIONS [LIMIT_S]}
out=${2:?usage: ppo_sweep.sh SWEEP_FILE OUT_DIR ITERATIONS [LIMIT_S]}
iters=${3:?usage: ppo_sweep.sh SWEEP_FILE OUT_DIR ITERATIONS [LIMIT_S]}
limit=${4:-0}
limiter=""
[[ "$limit" -gt 0 ]] && limiter="timeout $limit"
gpus=${GPUS:-1}
data=${WRESDYN_DATA:-data/dataset.npz}
w=${WRESDYN:-wresdyn}
export PYTHONUNBUFFERED=1
mkdir -p "$out"
i=0
pids=()
while read -r name args; do
  [[ -z "$name" || "$name" == \#* ]] && continue
  dev=cpu
  [[ "$gpus" -gt 0 ]] && dev="cuda:$((i % gpus))"
  # shellcheck disable=SC2086
  $limiter $w train "$data" --device "$dev" --iterations "$iters" --save-interval 50 --out "$out/$name" --eval $args \
      >> "$out/$name.log" 2>&1 &
  pids+=($!)
  i=$((i + 1))
done < "$sweep"
wait "${pids[@]}"
bash "$(dirname "$0")/sweep_summary.sh" "$sweep" "$out"
