#!/bin/bash
# Device job for a 2 x H200 host (the kind nvidia-h200-x2). Order, all launched at once:
#  GPU 0: one floor seed at full size, timed (benchmarks/skills/floor_seed_timing.sh, BESIDE=3: (c), (e), (f) each in
#         a process of its own on GPU 0 beside (b)), seed 3, default mismatch, a fresh folder;
#  GPU 1 (its own Warp cache): `wresdyn warmup`, then the gradient fit's 2000 iterations, fused against plain
#         (benchmarks/speed/gradfit10.sh), then the warm fit's tail in one process against the helpers, three pairs
#         (benchmarks/results/speed/tail57_plan.md: coldfit.sh with HELPER_PAIRS=3, each step its own cache), then
#         the gradient fit again with 16 and with 8 threads per block of the replay kernels (32 by default:
#         speed_paths/block_dim/ measured 256, 64 and 32, the adjoint fastest at 32);
#  host:  the two mujoco.sysid peers resumed from their committed checkpoints at nice 19 (16 threads each),
#         their --max-seconds ending 150 s before END.
#  On a 1-GPU host (the kind nvidia-h200) GPU 1's legs are left out while the seed runs; when it has ended and more
#  than 150 s are left before END, the warm fit's three pairs with and without the helpers (coldfit.sh, SHIPPED=1
#  HELPER_PAIRS=3) run on GPU 0 in the time left, so the seed's seconds are measured with nothing else on the GPU.
#  At END (epoch seconds) whatever still runs is stopped (the seed's script records its seconds with rc=stopped) and
#  the seed is packed for a resume.
# Usage (repository root; inputs in .dev/data: uneven.npz, peer_default/, peer_uneven/, COMMIT, read_logs.py and
# compare.py of benchmarks/results/speed/{tail57_cpu,warm57_cpu}/, which the slim tree leaves out): bash job.sh END_EPOCH
set -u
END=${1:?END epoch}
R=/root/res; mkdir -p $R /root/peer_out/default /root/peer_out/uneven data/uneven
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
cp .dev/data/uneven.npz data/uneven/dataset.npz
cp -r .dev/data/peer_default /root/peer_out/default/peer; cp -r .dev/data/peer_uneven /root/peer_out/uneven/peer
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep -E "Model name|NUMA"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat .dev/data/COMMIT)"; sha256sum data/dataset.npz data/uneven/dataset.npz; } > $R/machine.txt 2>&1
stage start
( BESIDE=3 GPU=0 bash benchmarks/skills/floor_seed_timing.sh /root/seedtime_beside > $R/seed.out 2>&1
  stage "seed ended rc=$?" ) &
SEED=$!
stage "seed launched on GPU 0"
PEER_S=$(( END - $(date +%s) - 150 ))
for m in default uneven; do
  ( UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh $m \
      peer --threads 16 --max-seconds $PEER_S --resume > $R/peer_$m.log 2>&1; stage "peer $m ended rc=$?" ) &
done
stage "peers launched (--max-seconds $PEER_S)"
[ "$(nvidia-smi -L | wc -l)" -ge 2 ] && ( export CUDA_VISIBLE_DEVICES=1 WARP_CACHE_PATH=/root/wc_gpu1
  { time python3 -m wresdyn.cli warmup --device cuda:0; } > $R/gradfit_warmup.log 2>&1
  stage "warmup ended rc=$?"
  TOTAL=300 bash benchmarks/speed/gradfit10.sh $R/gradfit10 > $R/gradfit10.log 2>&1
  stage "gradfit10 ended rc=$?"
  GPU=1 SHIPPED=1 HELPER_PAIRS=3 TOTAL=560 bash benchmarks/speed/coldfit.sh $R/coldfit > $R/coldfit.log 2>&1
  stage "coldfit ended rc=$?"
  python3 .dev/data/read_logs.py $R/coldfit/fit_warm_h*.log > $R/coldfit/tail.txt 2>&1
  for i in 1 2 3; do python3 .dev/data/compare.py $R/coldfit/runs/fit_warm_h0_$i \
    $R/coldfit/runs/fit_warm_hx_$i fit_warm_h0_$i fit_warm_hx_$i; done > $R/coldfit/compare.txt 2>&1
  for B in 16 8; do  # fewer threads per block than the default 32: the adjoint's worlds over more multiprocessors
    WRESDYN_REPLAY_BLOCK_DIM=$B TOTAL=240 bash benchmarks/speed/gradfit10.sh $R/gradfit_b$B > $R/gradfit_b$B.log 2>&1
    stage "gradfit block_dim $B ended rc=$?"; done ) &
stage "GPU 1 legs launched"
LEGS=0
if [ "$(nvidia-smi -L | wc -l)" -lt 2 ]; then
  ( while kill -0 $SEED 2>/dev/null; do sleep 5; done
    LEFT=$(( END - $(date +%s) - 30 ))
    if [ $LEFT -gt 150 ]; then
      stage "GPU 0 after the seed: coldfit with TOTAL=$LEFT"
      WARP_CACHE_PATH=/root/wc_after GPU=0 SHIPPED=1 HELPER_PAIRS=3 TOTAL=$LEFT \
        bash benchmarks/speed/coldfit.sh $R/coldfit > $R/coldfit.log 2>&1
      stage "coldfit ended rc=$?"
      python3 .dev/data/read_logs.py $R/coldfit/fit_warm_h*.log > $R/coldfit/tail.txt 2>&1
      for i in 1 2 3; do python3 .dev/data/compare.py $R/coldfit/runs/fit_warm_h0_$i \
        $R/coldfit/runs/fit_warm_hx_$i fit_warm_h0_$i fit_warm_hx_$i; done > $R/coldfit/compare.txt 2>&1
    else stage "GPU 0 after the seed: $LEFT s left, coldfit not run"; fi ) &
  LEGS=$!
fi
while [ $(date +%s) -lt $END ] && { kill -0 $SEED 2>/dev/null || pgrep -f "[h]umanoid.py peer" > /dev/null \
  || { [ $LEGS != 0 ] && kill -0 $LEGS 2>/dev/null; }; }; do
  sleep 5; done
if kill -0 $SEED 2>/dev/null; then stage "seed stopped at END"; pkill -TERM -f "[f]loor_seed_timing.sh"; fi
if pgrep -f "[h]umanoid.py peer" > /dev/null; then stage "peers stopped at END"; pkill -TERM -f "[h]umanoid.py peer"; fi
sleep 20; wait $SEED 2>/dev/null
python3 benchmarks/skills/floor_fair_pack.py $R/pack /root/seedtime_beside > $R/pack.log 2>&1
mkdir -p $R/seed; cp /root/seedtime_beside/{time.txt,time_v.txt,deploy.log,machine.txt,load.log} $R/seed/ 2>/dev/null
cp -r /root/peer_out $R/peer_out
stage packed
