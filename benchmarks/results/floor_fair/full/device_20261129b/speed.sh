#!/bin/bash
# GPU checks of the session's new paths, on GPU 0 beside three floor runs (a loaded GPU and host: STAGES says when).
R=$1; mkdir -p $R/speed
S=$R/speed
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
secs() { python3 -c "import time;print(round(time.time()-$1,1))"; }
export CUDA_CACHE_DISABLE=1
# 1. the GPU tests: captured validation replay, the fit's speed paths, the floor's captured refresh, prebuilt kernels
export WARP_CACHE_PATH=/root/wc_tests
python3 -m pytest -q -rA -p no:cacheprovider tests/sim/test_rollout_graph.py tests/learn/test_learner_speed_paths.py \
  tests/skills/test_randomize.py tests/sim/test_prebuilt.py > $S/gpu_tests.txt 2>&1; stage speed gpu tests rc=$?
# 2. one validation replay, eager against captured
python3 benchmarks/speed/validation_graph.py --device cuda:0 --repeats 10 --json $S/validation_graph.json \
  > $S/validation_graph.txt 2>&1; stage speed validation_graph rc=$?
# 3. the first iteration from an empty Warp cache, without prebuilt kernels
python3 benchmarks/speed/first_fit_profile.py --device cuda:0 --cache /root/wc_plain > $S/first_fit_profile_plain.txt 2>&1
stage speed profile plain rc=$?
# 4. the kernels a package built for this GPU would ship: warmup --export from an empty cache
s=$(date +%s.%N); WARP_CACHE_PATH=/root/wc_export python3 -m wresdyn.cli warmup --device cuda:0 --export /root/prebuilt \
  > $S/warmup_export.log 2>&1; rc=$?; echo "warmup --export: $(secs $s) s rc=$rc" >> $S/warmup_export.log
du -sh /root/prebuilt >> $S/warmup_export.log; find /root/prebuilt -type f | xargs ls -la >> $S/warmup_export.log
stage speed warmup export rc=$rc
# 5. with them: the first iteration and the whole cold fit, each from an empty Warp cache
export WRESDYN_PREBUILT_KERNELS=/root/prebuilt
python3 benchmarks/speed/first_fit_profile.py --device cuda:0 --cache /root/wc_pb > $S/first_fit_profile_prebuilt.txt 2>&1
stage speed profile prebuilt rc=$?
fit() {  # TAG (WARP_CACHE_PATH set by the caller)
  local s=$(date +%s.%N)
  python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 --eval --out /root/runs/fit_$1 > $S/fit_$1.log 2>&1
  local rc=$?; echo "whole command: $(secs $s) s rc=$rc" >> $S/fit_$1.log; cp /root/runs/fit_$1/fit.log $S/fit_$1.fitlog 2>/dev/null
  stage speed fit $1 rc=$rc
}
WARP_CACHE_PATH=/root/wc_fit fit cold_prebuilt
WARP_CACHE_PATH=/root/wc_fit fit warm
