#!/usr/bin/env bash
# one.sh TREE NAME [extra fit flags...]: the fit with --eval from TREE, stamped, the shell's whole-command clock last
tree=$1; name=$2; shift 2
export OMP_NUM_THREADS=1 WRESDYN_LOG_CLOCK=1 PYTHONPATH=$tree
cd $tree
rm -rf /tmp/fw57/runs/$name
s=$(date +%s.%N)
nice -n 5 /work/main/.venv/bin/python -m wresdyn.cli fit data/dataset.npz --eval --out /tmp/fw57/runs/$name "$@" > /tmp/fw57/runs/$name.log 2>&1
rc=$?
echo "whole command: $(echo "$(date +%s.%N) - $s" | bc) s rc=$rc $(date -u +%H:%M:%S) load $(cut -d' ' -f1-3 /proc/loadavg)" >> /tmp/fw57/runs/$name.log
