#!/usr/bin/env bash
# One H200: the 2000 iterations at 1024 windows on the tiles (each weight read transposed from global memory) twice and
# the fused path once, the CUDA tests of the tile path, the tile step, and one tile iteration's kernels at H = 64.
set -u
END=$1; R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
left() { echo $(( END - $(date +%s) )); }
{ date -u; nvidia-smi -L; python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"; \
  echo "tree: $(cat .dev/COMMIT)"; } > $R/machine.txt 2>&1
stage start
unset WRESDYN_TILE_BLOCK
export WRESDYN_ADJOINT_PIECES=0  # every fit on the one adjoint kernel, which warmup compiles
{ time timeout 150 python3 -m wresdyn.cli warmup --device cuda:0; } > $R/cli_warmup.log 2>&1; stage "cli warmup rc=$?"
fit=(python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --windows 1024)
timeout 90 "${fit[@]}" --iterations 20 --fused --tiles --json $R/warmup.json > $R/warmup.log 2>&1
stage "warmup rc=$?"
timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/tiles.json > $R/tiles.log 2>&1; stage "tiles rc=$?"
timeout 55 "${fit[@]}" --iterations 2000 --fused --json $R/fused.json > $R/fused.log 2>&1; stage "fused rc=$?"
timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/tiles2.json > $R/tiles2.log 2>&1
stage "tiles2 rc=$?"
[ $(left) -gt 40 ] && { timeout 30 python3 benchmarks/speed/tile_mlp_step.py --device cuda:0 --windows 1024 \
  --json $R/step.json > $R/step.txt 2>&1; stage "step rc=$?"; }
[ $(left) -gt 40 ] && { timeout 35 python3 benchmarks/speed/profile_gradfit.py --device cuda:0 --fused --tiles --top 12 \
  --json $R/profile_tiles.json > $R/profile_tiles.txt 2>&1; stage "profile tiles rc=$?"; }
[ $(left) -gt 40 ] && { timeout 60 python3 -m pytest -q -rA -p no:cacheprovider tests/learn/test_tile_mlp.py \
  -k "cuda or graph" > $R/tests.txt 2>&1; stage "tests rc=$?"; }
python3 .dev/summary.py $R > $R/summary.txt 2>&1 || true
echo done > $R/DONE
