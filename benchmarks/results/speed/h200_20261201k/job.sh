#!/usr/bin/env bash
# One H200: the 2000 iterations at 1024 windows on the tiles, twice (the weights' gradients per step from 32768 rows,
# the biases' as matrix-vector products).
set -u
END=$1; R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
{ date -u; nvidia-smi -L; python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"; \
  echo "tree: $(cat .dev/COMMIT)"; } > $R/machine.txt 2>&1
stage start
unset WRESDYN_TILE_BLOCK
export WRESDYN_ADJOINT_PIECES=0  # every fit on the one adjoint kernel, which warmup compiles
{ time timeout 100 python3 -m wresdyn.cli warmup --device cuda:0; } > $R/cli_warmup.log 2>&1; stage "cli warmup rc=$?"
fit=(python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --windows 1024)
timeout 60 "${fit[@]}" --iterations 20 --fused --tiles --json $R/warmup.json > $R/warmup.log 2>&1
stage "warmup rc=$?"
timeout 45 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/tiles.json > $R/tiles.log 2>&1; stage "tiles rc=$?"
timeout 45 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/tiles2.json > $R/tiles2.log 2>&1
stage "tiles2 rc=$?"
python3 .dev/summary.py $R > $R/summary.txt 2>&1 || true
echo done > $R/DONE
