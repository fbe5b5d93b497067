#!/usr/bin/env bash
# one.sh TREE NAME: the small fit from TREE, its log with the shell's whole-command seconds
export OMP_NUM_THREADS=1 WRESDYN_LOG_CLOCK=1 PYTHONPATH=$1
cd $1
rm -rf /tmp/coldfit60_runs/$2
s=$(date +%s.%N)
/work/main/.venv/bin/python -m wresdyn.cli fit data/dataset.npz --eval --iterations 40 --windows 8 --identify.iterations 40 --out /tmp/coldfit60_runs/$2 > /tmp/coldfit60_runs/$2.log 2>&1
rc=$?
echo "whole command: $(echo "$(date +%s.%N) - $s" | bc) s rc=$rc" >> /tmp/coldfit60_runs/$2.log
