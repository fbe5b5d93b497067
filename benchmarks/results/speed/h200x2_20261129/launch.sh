#!/bin/bash
# This session's device job (background): speed measurements on GPU 0 from empty caches, the humanoid fight's peers on
# the host's cores (nice 19), the uneven fight's wresdyn legs and the floor's redraw check on GPU 1, then the residual
# PPO's 2-GPU scaling (3 rounds) with everything else paused, then the floor seed. Results in /root/res.
R=/root/res; mkdir -p $R /root/runs
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
export CUDA_CACHE_DISABLE=1
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
secs() { python3 -c "import time;print(round(time.time()-$1,1))"; }
{ date -u; nvidia-smi; nproc; lscpu | grep "Model name"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  git log -1 --format='%H %s'; ls ~/.cache/warp 2>&1; } > $R/machine.txt 2>&1
stage start

# --- host cores: the humanoid fight (peers at nice 19, 16 threads each)
mkdir -p /root/peer_out && cp -r devdata/peer_default /root/peer_out/default
( OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh default peer --threads 16 \
    --max-seconds 1300 --resume > $R/peer_default.log 2>&1; stage peer default ended ) &
( s=$(date +%s.%N); nice -n 5 python3 -m wresdyn.cli collect --mismatch data/mismatch_uneven.toml --out /root/uneven \
    > $R/collect_uneven.log 2>&1; rc=$?; echo "collect: $(secs $s) s rc=$rc" >> $R/collect_uneven.log; stage uneven collected
  UNEVEN=/root/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh \
    uneven peer --threads 16 --max-seconds 1150 > $R/peer_uneven.log 2>&1; stage peer uneven ended ) &

# --- GPU 1: the uneven fight's wresdyn legs (fresh caches), the floor's redraw check, then the floor seed
waitfor() { local t=0; while [ ! -f $1 ] && [ $t -lt $2 ]; do sleep 5; t=$((t + 5)); done; }
gpu1() {
  export CUDA_VISIBLE_DEVICES=1
  waitfor /root/uneven/dataset.npz 900; waitfor /root/cold_done 600; sleep 5
  WARP_CACHE_PATH=/root/wc_unev_gpu UNEVEN=/root/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 \
    bash benchmarks/peers/humanoid.sh uneven wresdyn --device cuda:0 > $R/wresdyn_uneven_gpu.log 2>&1; stage uneven wresdyn gpu
  ( WARP_CACHE_PATH=/root/wc_unev_cpu UNEVEN=/root/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 \
    bash benchmarks/peers/humanoid.sh uneven wresdyn --device cpu > $R/wresdyn_uneven_cpu.log 2>&1; stage uneven wresdyn cpu ) &
  export WARP_CACHE_PATH=/root/wc_floor
  python3 benchmarks/skills/randomize_speed.py /root/runs/rand --device cuda:0 --worlds 4096 --iterations 5 --floor \
    > $R/randomize_speed_cuda.txt 2>&1; cp /root/runs/rand/*.json $R/ 2>/dev/null; stage randomize speed
  python3 -m pytest -q -rA -p no:cacheprovider tests/skills/test_randomize.py -k gpu > $R/randomize_gpu_tests.txt 2>&1
  stage randomize tests rc=$?
  touch /root/floor_started
  s=$(date +%s.%N)
  python3 -m wresdyn.cli deploy --floor --full --device cuda:0 --mismatch data/mismatch_default.toml --seed 0 \
    --nominal floor_nominal --out /root/floor_def_s0 --quiet > $R/floor_def_s0.log 2>&1
  rc=$?; echo "floor rc=$rc in $(secs $s) s" >> $R/floor_def_s0.log; stage floor ended
}
gpu1 &

# --- GPU 0: the first fit from empty caches, warm, after warmup; the bench's adjoints; the gradient fit's 2000 its
fit() {  # fit TAG (WARP_CACHE_PATH set by the caller)
  local s=$(date +%s.%N)
  CUDA_VISIBLE_DEVICES=0 python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 --eval --out /root/runs/fit_$1 \
    > $R/fit_$1.log 2>&1
  local rc=$?; echo "whole command: $(secs $s) s rc=$rc" >> $R/fit_$1.log; cp /root/runs/fit_$1/fit.log $R/fit_$1.fitlog 2>/dev/null
  stage fit $1
}
WARP_CACHE_PATH=/root/wc_fit fit cold
touch /root/cold_done
WARP_CACHE_PATH=/root/wc_fit fit warm
s=$(date +%s.%N); CUDA_VISIBLE_DEVICES=0 WARP_CACHE_PATH=/root/wc_wu python3 -m wresdyn.cli warmup --device cuda:0 \
  > $R/warmup.log 2>&1; rc=$?; echo "warmup: $(secs $s) s rc=$rc" >> $R/warmup.log; stage warmup
WARP_CACHE_PATH=/root/wc_wu fit after_warmup
CUDA_VISIBLE_DEVICES=0 python3 benchmarks/speed/first_fit_profile.py --device cuda:0 --cache /root/wc_prof \
  > $R/first_fit_profile_cuda.txt 2>&1; stage profile
for a in pieces one; do
  CUDA_VISIBLE_DEVICES=0 WARP_CACHE_PATH=/root/wc_fit python3 -m wresdyn.cli bench --device cuda:0 --solvers replay \
    --worlds 4096 16384 --adjoint $a --json $R/bench_$a.json > $R/bench_$a.txt 2>&1; stage bench $a
done
CUDA_VISIBLE_DEVICES=0 WARP_CACHE_PATH=/root/wc_fit python3 benchmarks/speed/time_to_fidelity.py --device cuda:0 \
  --learners gradient --windows 1024 --check 50 --out /root/runs/ttf > $R/gradfit_2000.txt 2>&1
cp /root/runs/ttf/results.json $R/gradfit_2000.json 2>/dev/null; stage gradfit

# --- both GPUs: the residual PPO's scaling, 3 rounds, the floor paused (SIGSTOP) meanwhile
waitfor /root/floor_started 900
pk() { pkill -$1 -f "wresdyn.cli deploy --floor" ; }
pk STOP; sleep 2; stage ppo rounds start; uptime >> $R/STAGES
for r in 1 2 3; do
  CUDA_VISIBLE_DEVICES=0 python3 -m torch.distributed.run --standalone --nproc_per_node 1 benchmarks/speed/ppo_scaling.py \
    --device cuda --iterations 15 --json $R/one_r$r.json --cases residual:4096 > $R/one_r$r.txt 2>&1
  CUDA_VISIBLE_DEVICES=0,1 python3 -m torch.distributed.run --standalone --nproc_per_node 2 benchmarks/speed/ppo_scaling.py \
    --device cuda --iterations 15 --json $R/two_r$r.json --cases residual:8192 > $R/two_r$r.txt 2>&1
  python3 benchmarks/speed/ppo_scaling.py --table $R/one_r$r.json $R/two_r$r.json > $R/table_r$r.txt 2>&1
  stage ppo round $r
done
pk CONT; stage ppo rounds end
if [ -f benchmarks/speed/physical_limit.py ]; then
  CUDA_VISIBLE_DEVICES=0 WARP_CACHE_PATH=/root/wc_fit python3 benchmarks/speed/physical_limit.py /root/runs/plim \
    --device cuda:0 --worlds 4096,16384 > $R/physical_limit.txt 2>&1; cp /root/runs/plim/* $R/ 2>/dev/null; stage physical limit
fi
echo done > $R/DONE; stage gpu0 done
