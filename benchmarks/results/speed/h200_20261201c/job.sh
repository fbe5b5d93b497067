#!/bin/bash
# Device job for a 1-GPU host (the kind nvidia-h200): the tape's rows (../steps57_cpu/) checked and timed on GPU 0 with
# nothing else on it, each leg given what is left before END:
#   1. the fits' CUDA-graph tests with WRESDYN_TAPE_ROWS=1 (rows on) and without (the default on CUDA), and the tape's
#      own tests (at most 240 s each);
#   2. `wresdyn warmup --device cuda:0`;
#   3. the 2000 iterations (benchmarks/speed/gradfit10.sh: fused first run, fused, plain) without rows, then with rows:
#      the same figures expected to the last digit, the training seconds compared;
#   4. one iteration at H = 64 profiled with rows, fused and plain (benchmarks/speed/profile_gradfit.py --top 40),
#      against ../h200_20261201b/ (the code before).
# Usage (repository root of the slim tree; this script copied to .dev/job.sh, since benchmarks/results does not travel;
# .dev/COMMIT the tree's commit): bash .dev/job.sh END_EPOCH. Results in /root/res.
set -u
END=${1:?END epoch}
R=/root/res; mkdir -p $R
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
left() { echo $(( END - $(date +%s) - 20 )); }
cap() { local t; t=$(left); [ $t -gt $1 ] && t=$1; echo $t; }
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; uptime
  python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"
  echo "tree: $(cat .dev/COMMIT)"; sha256sum data/dataset.npz; } > $R/machine.txt 2>&1
( while [ $(date +%s) -lt $END ]; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi \
  --query-gpu=utilization.gpu,memory.used --format=csv,noheader)" >> $R/load.log; sleep 30; done ) &
stage start
TESTS="tests/sim/test_tape_step.py tests/learn/test_learner_speed_paths.py tests/identify/test_sysid_graph.py"
for rows in 1 0; do
  T=$(cap 240)
  [ $T -gt 60 ] && { WRESDYN_TAPE_ROWS=$rows timeout $T python3 -m pytest -p no:cacheprovider -q -rA $TESTS \
    -k "cuda or graph or tape" > $R/pytest_rows$rows.log 2>&1; stage "pytest rows=$rows ended rc=$?"; }
done
T=$(left)
[ $T -gt 120 ] && { { time timeout $T python3 -m wresdyn.cli warmup --device cuda:0; } > $R/warmup.log 2>&1
  stage "warmup ended rc=$?"; }
for rows in 0 1; do
  T=$(cap 240)
  [ $T -gt 60 ] && { WRESDYN_TAPE_ROWS=$rows TOTAL=$T bash benchmarks/speed/gradfit10.sh $R/gradfit10_rows$rows \
    > $R/gradfit10_rows$rows.log 2>&1; stage "gradfit10 rows=$rows ended rc=$? (TOTAL=$T)"; }
done
python3 - $R > $R/rows_compare.txt 2>&1 <<'PY'
import json, sys
from pathlib import Path
r = Path(sys.argv[1])
for name in ("fused", "plain"):
    a, b = (r / f"gradfit10_rows{x}" / f"{name}.json" for x in (0, 1))
    if not (a.exists() and b.exists()):
        print(f"{name}: missing"); continue
    a, b = json.loads(a.read_text()), json.loads(b.read_text())
    same = all(a[k] == b[k] for k in ("final_loss", "final_validation", "best_validation", "best_iteration"))
    print(f"{name}: training {a['train_s']:.2f} s without rows, {b['train_s']:.2f} s with rows; "
          f"final loss, validation, best the same to the last digit: {same} "
          f"({a['final_loss']!r} / {b['final_loss']!r}, {a['final_validation']!r} / {b['final_validation']!r})")
PY
for mode in fused plain; do
  T=$(cap 90); flag=""; [ $mode = fused ] && flag=--fused
  [ $T -gt 30 ] && { WRESDYN_TAPE_ROWS=1 timeout $T python3 benchmarks/speed/profile_gradfit.py --device cuda:0 \
    --windows 1024 --horizon 64 --repeat 20 $flag --top 40 --json $R/profile_rows_$mode.json \
    > $R/profile_rows_$mode.txt 2>&1; stage "profile rows $mode ended rc=$?"; }
done
stage done
