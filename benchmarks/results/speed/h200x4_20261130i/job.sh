#!/bin/bash
# Device job (a 4 x H200 host; on a 2-GPU host FOUR=0 GPUS="0 1 0" GRAD_GPU=none). Order:
#  1. every GPU and the host idle: the residual PPO's scaling on 1, 2 and 4 GPUs, three rounds
#     (benchmarks/speed/ppo90.sh with PPO_ENV's settings), nothing else running;
#  2. then together: the uneven floor's candidate D of floor_fair/kick55/NEXT.md ((f) retrained on floor_unvp_s{0,1,2}
#     with C's flags and `--randomization.unseen-effort-scale 0.8 1.2`, (a)-(e) kept), one seed per GPU of GPUS;
#     the gradient fit's 2000 iterations (benchmarks/speed/gradfit10.sh, fused against plain) on GRAD_GPU after
#     `wresdyn warmup`; the two mujoco.sysid peers resumed from their committed checkpoints at nice 19 (16 threads
#     each, their --max-seconds ending 150 s before END);
#  3. at END (epoch seconds) whatever still runs is stopped (the floors checkpoint every 50 iterations, the peers
#     after every iteration) and the floors are packed for a resume.
# Usage (repository root; inputs in .dev/data*): PPO_ENV="..." GPUS="1 2 3" GRAD_GPU=0 bash job.sh END_EPOCH [SKIP_PPO]
set -u
END=${1:?END epoch}; SKIP_PPO=${2:-0}; GPUS=${GPUS:-1 2 3}; GRAD_GPU=${GRAD_GPU:-0}
R=/root/res; S=/root/srcd; mkdir -p $R $S /root/peer_out/default /root/peer_out/uneven data/uneven data/uneven_probe
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
cp .dev/data/uneven.npz data/uneven/dataset.npz; cp .dev/data/uneven_probe.npz data/uneven_probe/dataset.npz
cp -r .dev/data/unvp_fits .dev/data2/floor_unvp_s0 .dev/data2/floor_unvp_s1 .dev/data3/floor_unvp_s2 $S/
cp -r .dev/data/peer_default /root/peer_out/default/peer; cp -r .dev/data/peer_uneven /root/peer_out/uneven/peer
{ date -u; nvidia-smi; nvidia-smi topo -m; echo "cores: $(nproc --all)"; lscpu | grep -E "Model name|NUMA"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat .dev/data/COMMIT)"; sha256sum data/dataset.npz data/uneven/dataset.npz data/uneven_probe/dataset.npz
  ls $S; } > $R/machine.txt 2>&1
( while sleep 30; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi \
    --query-gpu=utilization.gpu,memory.used --format=csv,noheader | tr '\n' ' ')"; done ) >> $R/load.log 2>&1 &
stage start
if [ "$SKIP_PPO" = 0 ]; then
  env ${PPO_ENV:-} bash benchmarks/speed/ppo90.sh $R/ppo90 > $R/ppo90.log 2>&1
  stage "ppo ended rc=$?"
fi
PEER_S=$(( END - $(date +%s) - 150 ))
for m in default uneven; do
  ( UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh $m \
      peer --threads 16 --max-seconds $PEER_S --resume > $R/peer_$m.log 2>&1; stage "peer $m ended rc=$?" ) &
done
stage "peers launched (--max-seconds $PEER_S)"
I="--randomization.unseen wide --randomization.unseen-mass-add-kg -5 5 --randomization.unseen-com-offset 0.05 0.05 0.01"
( REUSE=1 BASE=floor_unvp NAME=floor_unvpd GPUS="$GPUS" KEEP="b_calibrated c_delta_action d_oracle e_randomized" \
    EXTRA="$I --randomization.unseen-effort-scale 0.8 1.2" bash benchmarks/skills/floor_fair_probe.sh $S $R/floors \
    > $R/floors.log 2>&1
  stage "floors ended rc=$?" ) &
FL=$!
stage "floors launched on GPUS $GPUS"
if [ "$GRAD_GPU" != none ]; then
  ( export CUDA_VISIBLE_DEVICES=$GRAD_GPU
    { time python3 -m wresdyn.cli warmup --device cuda:0; } > $R/gradfit_warmup.log 2>&1
    stage "gradfit warmup ended rc=$?"
    TOTAL=420 bash benchmarks/speed/gradfit10.sh $R/gradfit10 > $R/gradfit10.log 2>&1
    stage "gradfit10 ended rc=$?" ) &
  stage "gradfit launched on GPU $GRAD_GPU"
fi
while [ $(date +%s) -lt $END ] && { kill -0 $FL 2>/dev/null || pgrep -f "[h]umanoid.py peer" > /dev/null; }; do sleep 5; done
if kill -0 $FL 2>/dev/null; then stage "floors stopped at END"; pkill -TERM -f "[w]resdyn.cli deploy"; fi
if pgrep -f "[h]umanoid.py peer" > /dev/null; then stage "peers stopped at END"; pkill -TERM -f "[h]umanoid.py peer"; fi
sleep 20; wait $FL 2>/dev/null
python3 benchmarks/skills/floor_fair_pack.py $R/pack /root > $R/pack.log 2>&1
for d in $R/pack/floor_unv_s*; do [ -d "$d" ] && mv "$d" "${d/floor_unv_s/floor_unvpd_s}"; done
cp -r /root/peer_out $R/peer_out
stage packed
stage done
