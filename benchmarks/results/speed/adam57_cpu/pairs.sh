#!/bin/bash
# three alternating rounds: the small fit with its evaluation, HELPERS helper processes (1 by default) forced, on the
# tree before (/tmp/adam_before) and after (/tmp/adam_after), worktrees of 04d56e8~1 and 04d56e8;
# usage: [HELPERS=N] pairs.sh OUT
out=${1:?OUT}; mkdir -p $out
for i in 1 2 3; do for t in before after; do
  d=/tmp/adam_$t; rm -rf /tmp/adam57_run_$t
  s=$(date +%s.%N)
  (cd $d && PYTHONPATH=$d OMP_NUM_THREADS=1 WRESDYN_FIT_HELPERS=${HELPERS:-1} WRESDYN_LOG_CLOCK=1 /work/main/.venv/bin/python -X importtime \
    -m wresdyn.cli fit /work/main/data/dataset.npz --out /tmp/adam57_run_$t --device cpu --eval --iterations 4 \
    --identify.iterations 4 --windows 4 > $out/${t}_$i.log 2> $out/${t}_$i.importtime)
  rc=$?
  echo "whole command: $(python3 -c "import time; print(round(time.time() - $s, 1))") s rc=$rc" >> $out/${t}_$i.log
  grep -c "torch._dynamo$\| torch._dynamo\b" $out/${t}_$i.importtime > /dev/null
  echo "$t $i: $(grep -E '^\s*[0-9.]+ s start|start:' $out/${t}_$i.log | head -1) | dynamo imported in the fitting process: $(grep -cE '\| +torch\._dynamo$' $out/${t}_$i.importtime) | $(tail -1 $out/${t}_$i.log)" >> $out/pairs.txt
done; done
