#!/bin/bash
# On a fresh GPU machine, after the wheels' install.py, with PYTHONPATH exported by the caller: the first two
# `wresdyn fit` runs at the defaults (the first finds no one-kernel adjoint in Warp's cache: pieces, and the one
# kernel compiles in the background; the second finds it), each with its whole command's wall-clock. /root/res.
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
export CUDA_CACHE_DISABLE=1 WRESDYN_KERNEL_DIR=/root/ks_auto WARP_CACHE_PATH=/root/wc_auto
fit auto_first
ls -la --time-style=+%T.%N /root/wc_auto/*/ > $R/cache_after_first.txt
fit auto_second
echo done > $R/DONE
