#!/usr/bin/env bash
# Summary of a sweep's `--eval` logs, sorted by the validation error (the only split choices are made on):
#   bash benchmarks/fidelity/sweep_summary.sh SWEEP_FILE OUT_DIR
set -uo pipefail
sweep=${1:?usage: sweep_summary.sh SWEEP_FILE OUT_DIR}
out=${2:?usage: sweep_summary.sh SWEEP_FILE OUT_DIR}
echo "| run | validation mean abs dq [rad] (x) | held-out (x) | OOD (x) | args |"
echo "|---|---|---|---|---|"
while read -r name args; do
  [[ -z "$name" || "$name" == \#* ]] && continue
  row=""
  for split in validation heldout ood; do
    line=$(grep -h "^$split " "$out/$name.log" 2>/dev/null | tail -1)
    val=$(echo "$line" | sed -n 's/.*PD + residual \([0-9.]*\) .*(\([0-9.]*x\)).*/\1 (\2)/p')
    row="$row | ${val:--}"
  done
  echo "| $name$row | $args |"
done < "$sweep" | sort -t'|' -k3,3
