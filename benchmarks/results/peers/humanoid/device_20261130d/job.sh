#!/bin/bash
# Device job (2 x H200 host, fifth session). Order:
#  1. both GPUs idle: the residual PPO's scaling, three rounds (ITERS=50 BASELINE=0 benchmarks/speed/ppo90.sh);
#     the host's cores meanwhile: wresdyn's reported recipe refine_all_shared_delay on both humanoid mismatches (Warp
#     CPU backend, fresh kernel caches), then the two mujoco.sysid peers at nice 19 once both have ended;
#  2. the floor benchmark's uneven mismatch with the probe's corrections: REUSE=1 floor_fair_probe.sh, seeds 0 and 2
#     on GPU 0, seed 1 on GPU 1; meanwhile refine_all_shared_delay on one GPU each (default GPU 0, uneven GPU 1, fresh
#     kernel caches), sharing the GPU with the floors' first minutes (the motions are drawn on the CPU);
#  3. at FLOOR_S seconds after the floors started, every floor still running gets SIGTERM (each policy checkpoints
#     every 50 iterations; a later session resumes from the packed folders); packed into /root/pack.
# Usage (repository root; run folders in .dev/data*): bash job.sh PEER_SECONDS FLOOR_SECONDS
set -u
PEER_S=${1:-900}; FLOOR_S=${2:-900}
R=/root/res; mkdir -p $R /root/src /root/peer_out/default /root/peer_out/uneven
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
mkdir -p data/uneven data/uneven_probe
cp .dev/data2/uneven.npz data/uneven/dataset.npz; cp .dev/data2/uneven_probe.npz data/uneven_probe/dataset.npz
for d in .dev/data .dev/data2; do cp -r $d/floor_* $d/unvp_fits /root/src/ 2>/dev/null; done
cp -r .dev/data/peer_default /root/peer_out/default/peer; cp -r .dev/data/peer_uneven /root/peer_out/uneven/peer
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep "Model name"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat .dev/data/COMMIT)"; sha256sum data/uneven/dataset.npz data/uneven_probe/dataset.npz; ls /root/src; } > $R/machine.txt 2>&1
stage start
( while sleep 30; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi \
    --query-gpu=utilization.gpu,memory.used --format=csv,noheader | tr '\n' ' ')"; done ) >> "$R/load_all.log" 2>&1 &
refine() {  # DEVICE MISMATCH TAG [CUDA_VISIBLE_DEVICES]
  local t=$(date +%s)
  CUDA_VISIBLE_DEVICES=${4:-} WARP_CACHE_PATH=/root/wc_$3_$2 UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out \
    PYTHON=python3 bash benchmarks/peers/humanoid.sh $2 wresdyn --device $1 --recipe refine_all_shared_delay \
    --tag $3 > $R/$3_$2.log 2>&1
  stage $3 $2 rc=$? after $(( $(date +%s) - t )) s
}
# host: the CPU legs, then the peers
( refine cpu default refine_all_shared_delay_peer_host & refine cpu uneven refine_all_shared_delay_peer_host & wait
  stage cpu legs ended
  for m in default uneven; do
    ( UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh $m \
        peer --threads 16 --max-seconds $PEER_S --resume > $R/peer_$m.log 2>&1; stage peer $m ended rc=$? ) &
  done; wait ) &
HOST=$!
stage ppo start
ITERS=50 BASELINE=0 bash benchmarks/speed/ppo90.sh $R/ppo90 > $R/ppo90.log 2>&1
stage ppo ended rc=$?
( REUSE=1 GPUS="0 1" RUNS="floor_unvp_s0 floor_unvp_s1 floor_unvp_s2" bash benchmarks/skills/floor_fair_probe.sh \
    /root/src $R/floor > $R/floor_probe.log 2>&1; stage floors ended rc=$? ) &
FL=$!
stage floors launched
sleep 15
refine cuda:0 default refine_all_shared_delay_cuda 0 & refine cuda:0 uneven refine_all_shared_delay_cuda 1 &
t=$(date +%s)
while kill -0 $FL 2>/dev/null && [ $(( $(date +%s) - t )) -lt $FLOOR_S ]; do sleep 10; done
if kill -0 $FL 2>/dev/null; then
  stage floors stopped at $FLOOR_S s
  pkill -TERM -f "wresdyn.cli deploy"; sleep 20
fi
wait $FL 2>/dev/null
python3 benchmarks/skills/floor_fair_pack.py /root/pack/floors /root > $R/pack.log 2>&1
stage packed
