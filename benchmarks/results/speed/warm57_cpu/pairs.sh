#!/usr/bin/env bash
# Rounds of the small CPU fit with its evaluation, one run per variant and round, alternating, each into the same run
# folder (so the files compare byte for byte; the trees should sit at paths of one length, since torch.export and the
# ONNX file record the source paths), its log stamped (WRESDYN_LOG_CLOCK=1) and its whole wall time taken by the shell:
#   bash pairs.sh OUT ROUNDS TAG=TREE[:HELPER] ...
# TREE: a repository root (`git archive` of a commit); HELPER: 1 or 0 forces `--eval`'s helper process on or off
# (run_fit.py), none: the tree's own rule. OUT/<tag><round>.log, OUT/<tag><round>/ the run.
set -uo pipefail
out=$1 n=$2; shift 2
py=${PYTHON:-/work/main/.venv/bin/python}
here=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$out"
export OMP_NUM_THREADS=1 WRESDYN_LOG_CLOCK=1 PYTHONUNBUFFERED=1
for i in $(seq 1 "$n"); do
  for spec in "$@"; do
    tag=${spec%%=*} tree=${spec#*=} helper=
    case $tree in *:*) helper=${tree##*:} tree=${tree%:*};; esac
    rm -rf /tmp/warm57_pair_run
    s=$EPOCHREALTIME
    (cd "$tree" && env ${helper:+HELPER=$helper} PYTHONPATH="$tree" nice -n 5 "$py" "$here/run_fit.py" fit \
      data/dataset.npz --device cpu --eval --out /tmp/warm57_pair_run --iterations 4 --identify.iterations 4 \
      --windows 4) > "$out/$tag$i.log" 2>&1
    rc=$?
    e=$EPOCHREALTIME
    echo "whole command: $(python3 -c "print(round($e - $s, 2))") s rc=$rc load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/$tag$i.log"
    rm -rf "$out/$tag$i"; cp -r /tmp/warm57_pair_run "$out/$tag$i"
  done
done
