#!/usr/bin/env bash
# One H200: the plain path's 2000 iterations at 1024 windows run eagerly (no CUDA graph), for its final validation.
set -u
R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 WRESDYN_ADJOINT_PIECES=0
{ date -u; nvidia-smi -L; python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"; \
  echo "tree: $(cat .dev/COMMIT)"; } > $R/machine.txt 2>&1
echo "$(date -u +%T) start" >> $R/STAGES
timeout 230 python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --windows 1024 --iterations 2000 --no-graph \
  --json $R/plain_eager.json > $R/plain_eager.log 2>&1
echo "$(date -u +%T) plain_eager rc=$?" >> $R/STAGES
echo done > $R/DONE
