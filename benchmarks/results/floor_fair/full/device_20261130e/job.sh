#!/bin/bash
# Device job (2 x H200 host, eighth session). Order:
#  1. both GPUs idle, nothing else on the host: the residual PPO's scaling, three rounds, the default and the
#     CUDA-graph update (ITERS=50 BASELINE=0 GRAPH=1 benchmarks/speed/ppo90.sh), the graph's CUDA check first;
#  2. the floor benchmark's uneven mismatch on the probe's corrections, seeds 0 (GPU 0) and 2 (GPU 1), resumed from
#     the packed floor_unvp_s0/_s2 (REUSE=1 floor_fair_probe.sh); seed 1 finished in an earlier session;
#  3. at FLOOR_S seconds after the floors started, any still running gets SIGTERM; packed into /root/pack.
# Usage (repository root; run folders in .dev/data*): bash job.sh FLOOR_SECONDS
set -u
FLOOR_S=${1:-780}
R=/root/res; mkdir -p $R /root/src
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
mkdir -p data/uneven_probe
cp .dev/data/dataset.npz data/dataset.npz; cp .dev/data2/uneven_probe.npz data/uneven_probe/dataset.npz
cp -r .dev/data/floor_unvp_s0 .dev/data/unvp_fits .dev/data2/floor_unvp_s2 /root/src/
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep "Model name"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat .dev/data/COMMIT)"; sha256sum data/dataset.npz data/uneven_probe/dataset.npz; ls /root/src; } > $R/machine.txt 2>&1
stage start
( while sleep 30; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi \
    --query-gpu=utilization.gpu,memory.used --format=csv,noheader | tr '\n' ' ')"; done ) >> "$R/load_all.log" 2>&1 &
CUDA_VISIBLE_DEVICES=0 python3 -m pytest -p no:cacheprovider -q -x tests/ppo/test_graph_update.py \
  -k "within_rounding_on_cuda and not two" > $R/graph_precheck.txt 2>&1
G=$(( $? == 0 )); stage graph precheck GRAPH=$G
stage ppo start
ITERS=50 BASELINE=0 GRAPH=$G bash benchmarks/speed/ppo90.sh $R/ppo90 > $R/ppo90.log 2>&1
stage ppo ended rc=$?
( REUSE=1 GPUS="0 1" RUNS="floor_unvp_s0 floor_unvp_s2" bash benchmarks/skills/floor_fair_probe.sh \
    /root/src $R/floor > $R/floor_probe.log 2>&1; stage floors ended rc=$? ) &
FL=$!
stage floors launched
t=$(date +%s)
while kill -0 $FL 2>/dev/null && [ $(( $(date +%s) - t )) -lt $FLOOR_S ]; do sleep 10; done
if kill -0 $FL 2>/dev/null; then
  stage floors stopped at $FLOOR_S s
  pkill -TERM -f "[w]resdyn.cli deploy"; sleep 20
fi
wait $FL 2>/dev/null
python3 benchmarks/skills/floor_fair_pack.py /root/pack/floors /root > $R/pack.log 2>&1
stage packed
