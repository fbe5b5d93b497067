#!/usr/bin/env bash
# Rounds of the small CPU fit with its evaluation, one run per variant and round, alternating, each into the same run
# folder (so the files compare byte for byte; the trees sit at paths of one length, since torch.export and the ONNX
# file record the source paths), its log stamped (WRESDYN_LOG_CLOCK=1) and its whole wall time taken by the shell:
#   bash pairs.sh OUT ROUNDS TAG=TREE[:HELPERS] ...
# TREE: a repository root (`git archive` of a commit, data/dataset.npz in it); HELPERS: WRESDYN_FIT_HELPERS for the
# run (0: the tail in one process; 1 or 3: that many helper processes whatever the cores), none: the tree's own rule.
# OUT/<tag><round>.log, OUT/<tag><round>/ the run.
set -uo pipefail
out=$1 n=$2; shift 2
py=${PYTHON:-/work/main/.venv/bin/python}
mkdir -p "$out"
export OMP_NUM_THREADS=1 WRESDYN_LOG_CLOCK=1 PYTHONUNBUFFERED=1
unset WRESDYN_FIT_HELPERS
for i in $(seq 1 "$n"); do
  for spec in "$@"; do
    tag=${spec%%=*} tree=${spec#*=} helpers=
    case $tree in *:*) helpers=${tree##*:} tree=${tree%:*};; esac
    rm -rf /tmp/tail57_pair_run
    s=$EPOCHREALTIME
    (cd "$tree" && env ${helpers:+WRESDYN_FIT_HELPERS=$helpers} PYTHONPATH="$tree" nice -n 5 "$py" -m wresdyn.cli fit \
      data/dataset.npz --device cpu --eval --out /tmp/tail57_pair_run --iterations 4 --identify.iterations 4 \
      --windows 4) > "$out/$tag$i.log" 2>&1
    rc=$?
    e=$EPOCHREALTIME
    echo "whole command: $(python3 -c "print(round($e - $s, 2))") s rc=$rc load $(cut -d' ' -f1-3 /proc/loadavg)" >> "$out/$tag$i.log"
    rm -rf "$out/$tag$i"; cp -r /tmp/tail57_pair_run "$out/$tag$i"
  done
done
