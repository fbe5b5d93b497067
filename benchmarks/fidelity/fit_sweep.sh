#!/usr/bin/env bash
# Gradient-fit sweep: one `wresdyn fit --eval` per line of a sweep file, JOBS at a time (default 1), ranked by
# the validation error (the split choices are made on); held-out and OOD are printed for reporting only.
#
#   bash benchmarks/fidelity/fit_sweep.sh SWEEP_FILE OUT_DIR [JOBS]
#
# SWEEP_FILE: one run per line, `NAME ARGS...` (ARGS passed to `wresdyn fit`); blank lines and # comments skipped.
# Environment: WRESDYN (the CLI, default `wresdyn`), WRESDYN_DATA (default data/dataset.npz). Runs resume.
set -uo pipefail
sweep=${1:?usage: fit_sweep.sh SWEEP_FILE OUT_DIR [JOBS]}
out=${2:?usage: fit_sweep.sh SWEEP_FILE OUT_DIR [JOBS]}
jobs=${3:-1}
data=${WRESDYN_DATA:-data/dataset.npz}
w=${WRESDYN:-wresdyn}
export PYTHONUNBUFFERED=1
mkdir -p "$out"
while read -r name args; do
  [[ -z "$name" || "$name" == \#* ]] && continue
  while (( $(jobs -rp | wc -l) >= jobs )); do wait -n; done
  # shellcheck disable=SC2086
  $w fit "$data" --out "$out/$name" --eval $args > "$out/$name.log" 2>&1 &
done < "$sweep"
wait
bash "$(dirname "$0")/sweep_summary.sh" "$sweep" "$out"
