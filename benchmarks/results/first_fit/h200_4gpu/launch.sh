#!/bin/bash
# device: after install.py; PYTHONPATH exported by the caller
mkdir -p /root/res /root/runs /root/corr
cp -r .dev/corr_probe/* /root/corr/
export PYTHONUNBUFFERED=1
{ nvidia-smi; nproc; git log -1 --format=%H 2>/dev/null; python3 -c "import torch,warp;print(torch.__version__, warp.__version__)"; } > /root/res/machine.txt 2>&1
ts() { python3 -u -c '
import sys,time
t0=time.time()
for l in sys.stdin: sys.stdout.write(f"{time.time()-t0:8.2f} {l}")'; }
cd $PWD
( CUDA_VISIBLE_DEVICES=0,1 bash benchmarks/skills/floor_gpu.sh /root/runs/probe_seed2 /root/corr/calibrated /root/corr/delta_action /root/corr/data/dataset.npz --seed 2 --beside-devices cuda:1 > /root/res/seed2.out 2>&1 ) &
fitpair() {  # GPU FUSEDFLAG NAME
  export CUDA_VISIBLE_DEVICES=$1 WARP_CACHE_PATH=/root/wc_$3
  for pass in cold warm; do
    s=$(date +%s.%N)
    python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 $2 --eval --out /root/runs/fit_$3_$pass 2>&1 | ts > /root/res/fit_$3_$pass.log
    echo "whole command: $(python3 -c "import time;print(round(time.time()-$s,1))") s" >> /root/res/fit_$3_$pass.log
  done
}
( fitpair 2 --identify.fused fused ) &
( fitpair 3 --identify.no-fused stepped ) &
sleep 2; echo launched
