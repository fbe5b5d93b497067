#!/bin/bash
# Device job for a 1-GPU host (the kind nvidia-h200): the speed issue's open GPU measurements one after the other on
# GPU 0, nothing else on the GPU, each leg given what is left before END:
#   1. the warm fit's tail in one process against its helper processes, three alternating pairs after a cold fit with
#      the shipped kernels (benchmarks/speed/coldfit.sh, SHIPPED=1 HELPER_PAIRS=3; each step its own Warp cache);
#   2. the CUDA tests of the fits' Adam inside CUDA graphs (identification's and the gradient fit's captured steps),
#      at most 180 s; then `wresdyn warmup`, the gradient fit's 2000 iterations, fused against plain
#      (benchmarks/speed/gradfit10.sh);
#   3. the gradient fit again with 16 and with 8 threads per block of the replay kernels (32 by default).
#  host: the two mujoco.sysid peers resumed from their committed checkpoints at nice 19 (16 threads each), their
#  --max-seconds ending 150 s before END.
# Usage (repository root of the slim tree; this script copied to .dev/job.sh, since benchmarks/results does not travel;
# inputs in .dev/data: uneven.npz, peer_default/, peer_uneven/, COMMIT, read_logs.py and compare.py of
# benchmarks/results/speed/{tail57_cpu,warm57_cpu}/): bash .dev/job.sh END_EPOCH
set -u
END=${1:?END epoch}
R=/root/res; mkdir -p $R /root/peer_out/default /root/peer_out/uneven data/uneven
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
left() { echo $(( END - $(date +%s) - 20 )); }
cp .dev/data/uneven.npz data/uneven/dataset.npz
cp -r .dev/data/peer_default /root/peer_out/default/peer; cp -r .dev/data/peer_uneven /root/peer_out/uneven/peer
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep -E "Model name|NUMA"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat .dev/data/COMMIT)"; sha256sum data/dataset.npz data/uneven/dataset.npz; } > $R/machine.txt 2>&1
( while [ $(date +%s) -lt $END ]; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi \
  --query-gpu=utilization.gpu,memory.used --format=csv,noheader)" >> $R/load.log; sleep 30; done ) &
stage start
PEER_S=$(( END - $(date +%s) - 150 ))
for m in default uneven; do
  ( UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh $m \
      peer --threads 16 --max-seconds $PEER_S --resume > $R/peer_$m.log 2>&1; stage "peer $m ended rc=$?" ) &
done
stage "peers launched (--max-seconds $PEER_S)"
T=$(left); [ $T -gt 560 ] && T=560
stage "coldfit with TOTAL=$T"
GPU=0 SHIPPED=1 HELPER_PAIRS=3 TOTAL=$T bash benchmarks/speed/coldfit.sh $R/coldfit > $R/coldfit.log 2>&1
stage "coldfit ended rc=$?"
python3 .dev/data/read_logs.py $R/coldfit/fit_warm_h*.log > $R/coldfit/tail.txt 2>&1
for i in 1 2 3; do python3 .dev/data/compare.py $R/coldfit/runs/fit_warm_h0_$i \
  $R/coldfit/runs/fit_warm_hx_$i fit_warm_h0_$i fit_warm_hx_$i; done > $R/coldfit/compare.txt 2>&1
T=$(left); [ $T -gt 180 ] && T=180
[ $T -gt 60 ] && { timeout $T python3 -m pytest -p no:cacheprovider -q -rA tests/learn/test_adam.py \
  tests/identify/test_sysid_graph.py tests/learn/test_learner_speed_paths.py -k "cuda or graph or adam" \
  > $R/pytest_cuda.log 2>&1; stage "pytest (the optimiser's CUDA graph paths) ended rc=$?"; }
T=$(left)
if [ $T -gt 120 ]; then
  { time timeout $T python3 -m wresdyn.cli warmup --device cuda:0; } > $R/gradfit_warmup.log 2>&1
  stage "warmup ended rc=$?"
fi
T=$(left); [ $T -gt 330 ] && T=330
[ $T -gt 60 ] && { EXTRA_SEEDS="1 2" TOTAL=$T bash benchmarks/speed/gradfit10.sh $R/gradfit10 > $R/gradfit10.log 2>&1
  stage "gradfit10 ended rc=$? (TOTAL=$T)"; }
for B in 16 8; do  # fewer threads per block than the default 32: the adjoint's worlds over more multiprocessors
  T=$(left); [ $T -gt 240 ] && T=240
  [ $T -gt 60 ] && { WRESDYN_REPLAY_BLOCK_DIM=$B TOTAL=$T bash benchmarks/speed/gradfit10.sh $R/gradfit_b$B \
    > $R/gradfit_b$B.log 2>&1; stage "gradfit block_dim $B ended rc=$? (TOTAL=$T)"; }
done
while [ $(date +%s) -lt $END ] && pgrep -f "[h]umanoid.py peer" > /dev/null; do sleep 5; done
if pgrep -f "[h]umanoid.py peer" > /dev/null; then stage "peers stopped at END"; pkill -TERM -f "[h]umanoid.py peer"; fi
sleep 10
cp -r /root/peer_out $R/peer_out
stage done
