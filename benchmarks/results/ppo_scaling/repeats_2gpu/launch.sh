#!/bin/bash
# On a fresh machine of 2 GPUs, after the wheels' install.py, with PYTHONPATH exported by the caller:
# 1. a default `wresdyn fit` on GPU 0 with the one-kernel adjoint from the start (WRESDYN_ADJOINT_PIECES=0: its
#    compile in the batch), for its training time;
# 2. the residual PPO's scaling, repeated: three rounds of one GPU at 4096 worlds, then torchrun on two at 4096 each,
#    alternating, 2 untimed and 15 timed iterations per case (benchmarks/speed/ppo_scaling.py, as gpu_scaling.sh's steps 1-2).
# Results in /root/res.
R=/root/res; mkdir -p $R /root/runs
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 CUDA_CACHE_DISABLE=1 WARP_CACHE_PATH=/root/wc
{ nvidia-smi; nproc; python3 -c "import torch,warp;print(torch.__version__, warp.__version__)"; } > $R/machine.txt 2>&1
ts() { python3 -u -c '
import sys,time
t0=time.time()
for l in sys.stdin: sys.stdout.write(f"{time.time()-t0:8.2f} {l}")'; }
fit() {
  s=$(date +%s.%N)
  CUDA_VISIBLE_DEVICES=0 python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 --eval --out /root/runs/fit_$1 2>&1 | ts | grep -v "^ *[0-9.]* *\(identify\|fit\): [0-9]*/" > $R/fit_$1.log
  echo "whole command: $(python3 -c "import time;print(round(time.time()-$s,1))") s" >> $R/fit_$1.log
}
export WRESDYN_ADJOINT_PIECES=0
fit one_kernel
unset WRESDYN_ADJOINT_PIECES
for r in 1 2 3; do
  CUDA_VISIBLE_DEVICES=0 python3 -m torch.distributed.run --standalone --nproc_per_node 1 benchmarks/speed/ppo_scaling.py \
    --device cuda --iterations 15 --json $R/one_r$r.json --cases residual:4096 > $R/one_r$r.txt 2>&1
  CUDA_VISIBLE_DEVICES=0,1 python3 -m torch.distributed.run --standalone --nproc_per_node 2 benchmarks/speed/ppo_scaling.py \
    --device cuda --iterations 15 --json $R/two_r$r.json --cases residual:8192 > $R/two_r$r.txt 2>&1
  python3 benchmarks/speed/ppo_scaling.py --table $R/one_r$r.json $R/two_r$r.json > $R/table_r$r.txt 2>&1
done
echo done > $R/DONE
