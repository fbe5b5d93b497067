#!/usr/bin/env bash
# One H200: the tile path's 2000 iterations at 1024 windows twice (the tree of main); the plain path's rounding floor
# with the nudges later in the schedule (after iteration 1667, where the 64-step windows begin, and after 1000).
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
for n in tiles tiles2; do
  timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/$n.json > $R/$n.log 2>&1; stage "$n rc=$?"
done
floor=(python3 benchmarks/speed/rounding_floor.py --device cuda:0 --windows 1024 --iterations 2000 --nudges 1,2)
for at in 1667 1000; do
  [ $(left) -gt 120 ] && { timeout 115 "${floor[@]}" --at $at --json $R/floor_plain_$at.json > $R/floor_plain_$at.txt \
    2>&1; stage "floor $at rc=$?"; }
done
python3 .dev/summary.py $R > $R/summary.txt 2>&1 || true
echo done > $R/DONE
