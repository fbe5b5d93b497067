#!/usr/bin/env bash
# One H200: where the fused paths part from the plain one (one batch's gradients at H = 2, 17, 64, Adam steps, the
# loss's time); the tile path's 2000 iterations at 1024 windows with the window loss as two Warp kernels (this tree) and
# without (.dev/old, the tree before it), interleaved, twice each; the tile path's 2000 iterations run eagerly (no
# CUDA graph); the CUDA tests of the fused path; one tile iteration's kernels at H = 64.
set -u
END=$1; R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
left() { echo $(( END - $(date +%s) )); }
{ date -u; nvidia-smi -L; python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"; \
  echo "tree: $(cat .dev/COMMIT); old: $(cat .dev/OLD_COMMIT)"; } > $R/machine.txt 2>&1
stage start
unset WRESDYN_TILE_BLOCK
export WRESDYN_ADJOINT_PIECES=0  # every fit on the one adjoint kernel, which warmup compiles
{ time timeout 150 python3 -m wresdyn.cli warmup --device cuda:0; } > $R/cli_warmup.log 2>&1; stage "cli warmup rc=$?"
fit=(python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --windows 1024)
timeout 90 "${fit[@]}" --iterations 20 --fused --tiles --json $R/warmup.json > $R/warmup.log 2>&1
stage "warmup rc=$?"
timeout 80 python3 benchmarks/speed/gradfit_paths.py --device cuda:0 --windows 1024 --tiles --horizons 2,17,64 \
  --json $R/paths.json > $R/paths.txt 2>&1; stage "paths rc=$?"
ln -sfn $PWD/data /root/old/data
OLDPATH=${PYTHONPATH/$PWD/\/root\/old}
old() { (cd /root/old && PYTHONPATH=$OLDPATH timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/$1.json \
  > $R/$1.log 2>&1); stage "$1 rc=$?"; }
new() { timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/$1.json > $R/$1.log 2>&1; stage "$1 rc=$?"; }
new tiles; old old_tiles; new tiles2; old old_tiles2
[ $(left) -gt 150 ] && { timeout 140 "${fit[@]}" --iterations 2000 --fused --tiles --no-graph --json $R/eager.json \
  > $R/eager.log 2>&1; stage "eager rc=$?"; }
[ $(left) -gt 40 ] && { timeout 35 python3 benchmarks/speed/profile_gradfit.py --device cuda:0 --fused --tiles \
  --horizon 64 --top 40 --json $R/profile_h64.json > $R/profile_h64.txt 2>&1; stage "profile h64 rc=$?"; }
[ $(left) -gt 30 ] && { timeout $(( $(left) - 15 )) python3 -m pytest -q -rA -p no:cacheprovider \
  tests/fit/test_fused_loss.py tests/fit/test_fused_network.py > $R/tests.txt 2>&1; stage "tests rc=$?"; }
python3 .dev/summary.py $R > $R/summary.txt 2>&1 || true
echo done > $R/DONE
