#!/bin/bash
# GPU checks on an idle GPU (the caller sets CUDA_VISIBLE_DEVICES): the CUDA-graph race checks, the gradient fit's
# 2000 iterations. R: results folder.
R=$1; S=$R/speed; mkdir -p $S
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
export WARP_CACHE_PATH=/root/wc_speed
# 1. the stream-race reproducer under load (its own 3 loader processes), after the fixes
timeout 240 python3 benchmarks/speed/graph_race.py --device cuda:0 --load 3 --repeats 5 > $S/graph_race_load3.txt 2>&1
stage speed graph_race rc=$?
# 2. the four graph tests and the 2-process floor skill test that failed on a loaded GPU
timeout 300 python3 -m pytest -q -rA -p no:cacheprovider tests/learn/test_learner_speed_paths.py tests/learn/test_gradfit_2000.py \
  -k "graph_replayed or torchrun_trains_a_floor" > $S/graph_tests.txt 2>&1; stage speed graph tests rc=$?
# 3. the gradient fit's 2000 iterations (benchmarks/speed/gradfit_2000.py)
timeout 240 python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --iterations 2000 --windows 1024 \
  --json $S/gradfit_2000.json > $S/gradfit_2000.txt 2>&1; stage speed gradfit rc=$?
