#!/bin/bash
# device: after install.py; PYTHONPATH exported by the caller. A fresh H200, an empty Warp cache, the replay kernels in
# blocks of 32: the first two default `wresdyn fit` runs (the second once the detached one-kernel compile has finished),
# then the online adapter's per-part profile at 8, 64 and 256 windows per update. Results in /root/res.
R=/root/res; mkdir -p $R /root/runs
export PYTHONUNBUFFERED=1
{ nvidia-smi; nproc; python3 -c "import torch,warp;print(torch.__version__, warp.__version__)"; } > $R/machine.txt 2>&1
ts() { python3 -u -c '
import sys,time
t0=time.time()
for l in sys.stdin: sys.stdout.write(f"{time.time()-t0:8.2f} {l}")'; }
fit() {  # NAME: one whole `wresdyn fit`, timestamped, with the command's wall-clock at the end
  s=$(date +%s.%N)
  python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 --eval --out /root/runs/fit_$1 2>&1 | ts > $R/fit_$1.log
  echo "whole command: $(python3 -c "import time;print(round(time.time()-$s,1))") s" >> $R/fit_$1.log
}
export CUDA_CACHE_DISABLE=1 WARP_CACHE_PATH=/root/wc
fit first
s=$(date +%s)
while pgrep -f compile_worker.py > /dev/null; do sleep 1; done
echo "detached one-kernel compile still running after the first fit's exit for $(( $(date +%s) - s )) s" > $R/background_wait.txt
fit second
echo fits > $R/STAGE
for w in 8 64 256; do python3 benchmarks/speed/adapt_profile.py --device cuda --set windows=$w > $R/adapt_profile_cuda_w$w.txt 2>&1; done
echo done > $R/DONE
