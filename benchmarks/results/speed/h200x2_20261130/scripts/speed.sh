#!/bin/bash
# GPU checks (the caller sets CUDA_VISIBLE_DEVICES). Usage: bash speed.sh R checks|gradfit
#   checks:  the CUDA-graph stream-race reproducer and the graph tests, on a GPU loaded by three floor trainings (the
#            condition they failed under before the fixes);
#   gradfit: the gradient fit's 2000 iterations at 1024 windows, on an idle GPU.
R=$1; S=$R/speed; mkdir -p $S
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
if [ "$2" = checks ]; then
  export WARP_CACHE_PATH=/root/wc_checks
  timeout 300 python3 benchmarks/speed/graph_race.py --device cuda:0 --load 3 --repeats 5 > $S/graph_race_load3.txt 2>&1
  stage speed graph_race rc=$?
  timeout 420 python3 -m pytest -q -rA -p no:cacheprovider tests/learn/test_learner_speed_paths.py \
    tests/learn/test_gradfit_2000.py -k "graph_replayed or torchrun_trains_a_floor" > $S/graph_tests.txt 2>&1
  stage speed graph tests rc=$?
else
  export WARP_CACHE_PATH=/root/wc_gradfit
  timeout 300 python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --iterations 2000 --windows 1024 \
    --json $S/gradfit_2000.json > $S/gradfit_2000.txt 2>&1; stage speed gradfit rc=$?
fi
