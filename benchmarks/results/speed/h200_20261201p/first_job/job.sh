#!/usr/bin/env bash
# One H200: the tile path's 2000 iterations at 1024 windows with its rollout as one autograd node (tape_chain, this
# tree's default) against the step loop (WRESDYN_ROLLOUT_CHAIN=0, the same tree) and the tree before (dbd389a,
# .dev/old), interleaved; the plain path once; the CUDA tests of the chain, tiles and fused path; one chained tile
# iteration's kernels at H = 64; the first fit on a fresh cache (shipped kernels) and warm, with the tile path and
# with the default.
set -u
END=$1; R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
left() { echo $(( END - $(date +%s) )); }
{ date -u; nvidia-smi -L; nproc; python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"; \
  echo "tree: $(cat .dev/COMMIT); old: $(cat .dev/OLD_COMMIT)"; } > $R/machine.txt 2>&1
stage start
unset WRESDYN_TILE_BLOCK
export WRESDYN_ADJOINT_PIECES=0  # every fit on the one adjoint kernel, which warmup compiles
{ time timeout 150 python3 -m wresdyn.cli warmup --device cuda:0; } > $R/cli_warmup.log 2>&1; stage "cli warmup rc=$?"
fit=(python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --windows 1024)
ln -sfn $PWD/data /root/old/data
OLDPATH=${PYTHONPATH/$PWD/\/root\/old}
timeout 90 "${fit[@]}" --iterations 20 --fused --tiles --json $R/warmup.json > $R/warmup.log 2>&1; stage "warmup rc=$?"
(cd /root/old && PYTHONPATH=$OLDPATH timeout 90 "${fit[@]}" --iterations 20 --fused --tiles --json $R/warmup_old.json \
  > $R/warmup_old.log 2>&1); stage "warmup old rc=$?"
new() { timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/$1.json > $R/$1.log 2>&1; stage "$1 rc=$?"; }
loop() { WRESDYN_ROLLOUT_CHAIN=0 timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/$1.json \
  > $R/$1.log 2>&1; stage "$1 rc=$?"; }
old() { (cd /root/old && PYTHONPATH=$OLDPATH timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/$1.json \
  > $R/$1.log 2>&1); stage "$1 rc=$?"; }
new chain1; loop loop1; old old1; new chain2; loop loop2; new chain3
[ $(left) -gt 100 ] && { timeout 90 python3 -m pytest -q -rA -p no:cacheprovider tests/sim/test_tape_chain.py \
  tests/learn/test_tile_mlp.py tests/fit/test_fused_network.py tests/sim/test_tape_step.py > $R/tests.txt 2>&1; \
  stage "tests rc=$?"; }
[ $(left) -gt 40 ] && { timeout 35 python3 benchmarks/speed/profile_gradfit.py --device cuda:0 --fused --tiles \
  --horizon 64 --top 40 --json $R/profile_h64.json > $R/profile_h64.txt 2>&1; stage "profile h64 rc=$?"; }
[ $(left) -gt 150 ] && { SHIPPED=1 HELPER_PAIRS=0 TOTAL=140 FIT_EXTRA="--fused-network --network-tiles" \
  bash benchmarks/speed/coldfit.sh $R/coldfit_tiles > $R/coldfit_tiles.out 2>&1; stage "coldfit tiles rc=$?"; }
[ $(left) -gt 60 ] && { timeout 55 "${fit[@]}" --iterations 2000 --json $R/plain.json > $R/plain.log 2>&1; \
  stage "plain rc=$?"; }
[ $(left) -gt 150 ] && { SHIPPED=1 HELPER_PAIRS=0 TOTAL=140 bash benchmarks/speed/coldfit.sh $R/coldfit_plain \
  > $R/coldfit_plain.out 2>&1; stage "coldfit plain rc=$?"; }
python3 .dev/summary.py $R > $R/summary.txt 2>&1 || true
echo done > $R/DONE
