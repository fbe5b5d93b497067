#!/usr/bin/env bash
# One H200: the tile path's 2000 iterations at 1024 windows with the window loss as two Warp kernels (this tree) and
# without (the tree before it, .dev/old), interleaved, twice each; the plain path's rounding floor (one-ULP nudges of
# its weights after iteration 1, resumed); the CUDA tests of the fused path; one tile iteration's kernels at H = 2
# and 64.
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
ln -sfn $PWD/data /root/old/data
OLDPATH=${PYTHONPATH/$PWD/\/root\/old}
old() { (cd /root/old && PYTHONPATH=$OLDPATH timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/$1.json \
  > $R/$1.log 2>&1); stage "$1 rc=$?"; }
new() { timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/$1.json > $R/$1.log 2>&1; stage "$1 rc=$?"; }
new tiles; old old_tiles; new tiles2; old old_tiles2
[ $(left) -gt 170 ] && { timeout 165 python3 benchmarks/speed/rounding_floor.py --device cuda:0 --windows 1024 \
  --iterations 2000 --nudges 1,2,3 --json $R/floor_plain.json > $R/floor_plain.txt 2>&1; stage "floor rc=$?"; }
[ $(left) -gt 70 ] && { timeout 65 python3 -m pytest -q -rA -p no:cacheprovider tests/fit/test_fused_network.py \
  tests/fit/test_fused_loss.py > $R/tests.txt 2>&1; stage "tests rc=$?"; }
for h in 2 64; do
  [ $(left) -gt 40 ] && { timeout 35 python3 benchmarks/speed/profile_gradfit.py --device cuda:0 --fused --tiles \
    --horizon $h --top 40 --json $R/profile_h$h.json > $R/profile_h$h.txt 2>&1; stage "profile h$h rc=$?"; }
done
python3 .dev/summary.py $R > $R/summary.txt 2>&1 || true
echo done > $R/DONE
