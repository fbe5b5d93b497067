#!/usr/bin/env bash
# pair.sh BEFORE_TREE AFTER_TREE OUT N [FIT FLAGS...]: N pairs of the same fit, before then after, back to back, each
# `wresdyn fit data/dataset.npz --device cpu --eval` from its tree (run there, PYTHONPATH naming it), its fit lines
# stamped (WRESDYN_LOG_CLOCK=1) and its whole-command seconds on the last line of OUT/<before|after><i>.log; the
# run folders in /tmp/startup_cpu_runs/, the load average before each run in OUT/load.txt.
set -u
before=$1 after=$2 out=$3 n=$4; shift 4
py=${PYTHON:-/work/main/.venv/bin/python}
mkdir -p "$out" /tmp/startup_cpu_runs
one() {  # one TREE NAME FLAGS...
  local tree=$1 name=$2; shift 2
  echo "$name $(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/load.txt"
  rm -rf "/tmp/startup_cpu_runs/$name"
  local s; s=$(date +%s.%N)
  (cd "$tree" && WRESDYN_LOG_CLOCK=1 OMP_NUM_THREADS=1 PYTHONUNBUFFERED=1 PYTHONPATH=$tree nice -n 5 "$py" -m wresdyn.cli \
    fit data/dataset.npz --device cpu --eval --out "/tmp/startup_cpu_runs/$name" "$@") > "$out/$name.log" 2>&1
  echo "whole command: $(python3 -c "import time; print(round(time.time() - $s, 2))") s rc=$?" >> "$out/$name.log"
}
for i in $(seq 1 "$n"); do
  one "$before" "before$i" "$@"
  one "$after" "after$i" "$@"
done
