#!/usr/bin/env bash
# PPO hyper-parameter sweep on a GPU host: one `wresdyn train` per line of a sweep file, spread round-robin
# over the GPUs, all at once, each under a wall-clock limit. Run it again with more iterations to extend the
# runs (they resume from their checkpoints); finished runs are evaluated (held-out and OOD) and summarised.
#
#   bash benchmarks/ppo_sweep.sh SWEEP_FILE OUT_DIR ITERATIONS [LIMIT_S]
#
# SWEEP_FILE: one run per line, `NAME ARGS...`, ARGS passed to `wresdyn train` (e.g. --set ppo.desired_kl=0.06);
# blank lines and lines starting with # are skipped. Environment: GPUS (number of GPUs, default 1; 0 runs on
# the CPU), WRESDYN (the CLI, default `wresdyn`), WRESDYN_DATA (default data/dataset.npz). Prints one line
# per run: name, iterations reached, held-out and OOD factor when evaluated.
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
while read -r name args; do
  [[ -z "$name" || "$name" == \#* ]] && continue
  last=$(ls "$out/$name" 2>/dev/null | sed -n 's/^model_\([0-9]*\)\.pt$/\1/p' | sort -n | tail -1)
  held=$(grep -h "^heldout" "$out/$name.log" | tail -1 | grep -o "([0-9.]*x)")
  ood=$(grep -h "^ood" "$out/$name.log" | tail -1 | grep -o "([0-9.]*x)")
  echo "$name it=${last:-0} heldout=${held:--} ood=${ood:--} :: $args"
done < "$sweep"
