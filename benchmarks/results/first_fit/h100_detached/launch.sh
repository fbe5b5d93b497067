#!/bin/bash
# On a fresh GPU machine, after the wheels' install.py, with PYTHONPATH exported by the caller: the first two
# `wresdyn fit` runs at the defaults (--eval on the fit's device; the one-kernel adjoint compiles in a detached worker
# that the first run does not wait for; the second run starts once it has finished), then the online adapter on the
# GPU: its per-part profile and the realtime command. Results in /root/res.
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
ls -la --time-style=+%T.%N /root/wc/*/ > $R/cache_after_first.txt
fit second
python3 benchmarks/speed/adapt_profile.py --device cuda --cprofile 30 > $R/adapt_profile_cuda.txt 2>&1
python3 benchmarks/speed/adapt_profile.py --device cpu > $R/adapt_profile_cpu.txt 2>&1
s=$(date +%s.%N)
python3 -m wresdyn.cli adapt benchmarks/results/grey_box/soft_friction data/dataset.npz --split validation,heldout --quiet --out /root/runs/adapt_rt --device cuda > $R/adapt_rt.log 2>&1
echo "whole command: $(python3 -c "import time;print(round(time.time()-$s,1))") s" >> $R/adapt_rt.log
cp /root/runs/adapt_rt/adapt.log $R/adapt_rt_adapt.log 2>/dev/null
echo done > $R/DONE
