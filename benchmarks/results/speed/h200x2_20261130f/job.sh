#!/bin/bash
# Device job, first hold of the session (2 x H200 host). Order:
#  1. the uneven floor with the effort line search's corrections (unvp55), seeds 0 (GPU 0) and 1 (GPU 1), and beside
#     them the opt-in CUDA-graph paths' CUDA tests (correctness only: they share the GPUs with the floors);
#  2. when the floors have ended or been stopped at FLOOR_S and packed: the residual PPO's rounds with the graph update
#     (ITERS=50 BASELINE=0 GRAPH=1 ppo90.sh) on idle GPUs if its check passed; otherwise the identification schedule
#     sweep (benchmarks/speed/identify_schedules.sh) on both GPUs.
# Usage (repository root; run folders in .dev/data*): bash job.sh FLOOR_SECONDS
set -u
FLOOR_S=${1:-780}
R=/root/res; S=/root/src55; mkdir -p $R $S/unvp55_fits $S/unvp_fits
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
mkdir -p data/uneven_probe
cp .dev/data/dataset.npz data/dataset.npz; cp .dev/data/uneven_probe.npz data/uneven_probe/dataset.npz
cp -r .dev/data/unvp55_calibrated $S/unvp55_fits/calibrated; cp -r .dev/data/delta_action $S/unvp_fits/delta_action
cp -r .dev/data2/floor_unvp_s0 .dev/data2/floor_unvp_s1 $S/
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep "Model name"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat .dev/data/COMMIT)"; sha256sum data/dataset.npz data/uneven_probe/dataset.npz; ls $S; } > $R/machine.txt 2>&1
stage start
( FLOOR_S=$FLOOR_S STAGES=floors55 bash benchmarks/speed/device_session.sh $R/floors $S; stage floors ended ) &
FL=$!
sleep 15
STAGES=checks bash benchmarks/speed/device_session.sh $R/checks
stage checks ended
wait $FL
if grep -q "check ppo_graph rc=0" $R/checks/STAGES; then
  stage ppo start
  ITERS=50 BASELINE=0 GRAPH=1 bash benchmarks/speed/ppo90.sh $R/ppo90 > $R/ppo90.log 2>&1
  stage ppo ended rc=$?
else
  stage sweep start
  bash benchmarks/speed/identify_schedules.sh $R/sweep > $R/sweep.log 2>&1
  stage sweep ended rc=$?
fi
stage done
