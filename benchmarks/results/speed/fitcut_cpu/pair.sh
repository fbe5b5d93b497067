#!/usr/bin/env bash
# before (tree at 5bfd26b, /tmp/fitcut_before) then after (the worktree), one after the other, nothing else of mine running
export OMP_NUM_THREADS=1 WRESDYN_LOG_CLOCK=1
for side in before after; do
  if [ $side = before ]; then cd /tmp/fitcut_before; export PYTHONPATH=/tmp/fitcut_before; else cd /work/wt/fitcut; export PYTHONPATH=/work/wt/fitcut; fi
  rm -rf /tmp/fitcut_runs/${side}2
  s=$(date +%s.%N)
  /work/main/.venv/bin/python -m wresdyn.cli fit data/dataset.npz --eval --iterations 40 --windows 8 --identify.iterations 40 --out /tmp/fitcut_runs/${side}2 > /tmp/fitcut_runs/${side}2.log 2>&1
  rc=$?
  echo "whole command: $(echo "$(date +%s.%N) - $s" | bc) s rc=$rc" >> /tmp/fitcut_runs/${side}2.log
done
