#!/bin/bash
# The A/B runs of this folder. They ran through a wrapper that set SolverReplay's CUDA default before running the
# command (`benchmarks/speed/adjoint_pieces.py run PIECES ...`, since replaced by the environment variable below, which
# fixes the same choice); everything else as run. After the wheels' install.py, PYTHONPATH exported by the caller.
R=/root/res; mkdir -p $R /root/runs
export PYTHONUNBUFFERED=1
ts() { python3 -u -c '
import sys,time
t0=time.time()
for l in sys.stdin: sys.stdout.write(f"{time.time()-t0:8.2f} {l}")'; }
fit() {  # NAME PIECES
  s=$(date +%s.%N)
  WRESDYN_ADJOINT_PIECES=$2 python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 --eval \
    --out /root/runs/fit_$1 2>&1 | ts > $R/fit_$1.log
  echo "whole command: $(python3 -c "import time;print(round(time.time()-$s,1))") s" >> $R/fit_$1.log
}
export CUDA_CACHE_DISABLE=1 WRESDYN_KERNEL_DIR=/root/ks_pieces WARP_CACHE_PATH=/root/wc_pieces
fit pieces_cold 400
fit pieces_warm 400
[ -d /root/wc_mono ] || cp -r .dev/wc_sm90_mono /root/wc_mono   # prefill_cuda_cache.py --pieces 0, carried
export WRESDYN_KERNEL_DIR=/root/ks_mono WARP_CACHE_PATH=/root/wc_mono
fit mono_prefilled 0
fit mono_warm 0
unset CUDA_CACHE_DISABLE
python3 benchmarks/speed/adjoint_pieces.py check --device cuda:0 --worlds 1024 --steps 64 > $R/check.txt 2>&1
for p in 400 0; do WRESDYN_ADJOINT_PIECES=$p python3 benchmarks/speed/learners.py --device cuda:0 --envs "" --graphs on \
  --windows 1024 --grad-iterations 30 > $R/learners_$p.txt 2>&1; done
