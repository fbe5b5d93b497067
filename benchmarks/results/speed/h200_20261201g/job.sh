#!/usr/bin/env bash
# One H200: the tile tests at TileBlock's default split, the step over splits with more threads, then the 2000
# iterations at 1024 windows: torch fused, the tiles at the default split and at the fastest split if another.
set -u
END=$1; R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
{ date -u; nvidia-smi -L; python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"; \
  echo "tree: $(cat .dev/COMMIT)"; } > $R/machine.txt 2>&1
stage start
unset WRESDYN_TILE_BLOCK
timeout 120 python3 -m pytest -q -rA -p no:cacheprovider tests/learn/test_tile_mlp.py > $R/tests.txt 2>&1
stage "tests rc=$?"
BLOCKS=8x32x256,8x32x512,16x32x512,16x64x512,8x16x256,32x32x1024,8x32x1024
timeout 120 python3 benchmarks/speed/tile_mlp_step.py --device cuda:0 --windows 1024 --blocks $BLOCKS \
  --json $R/step.json > $R/step.txt 2>&1; stage "step rc=$?"
BEST=$(python3 - <<'P'
import json
d = json.load(open("/root/res/step.json"))
ok = [t for t in d["tiles"] if "graph_us_per_step" in t]
b = min(ok, key=lambda t: t["graph_us_per_step"])["block"]
print(f"{b['rows']}x{b['chunk']}x{b['threads']}" + ("m" if b["mathdx"] else ""))
P
)
echo "$BEST" > $R/best.txt; stage "best $BEST"
fit=(python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --windows 1024)
WRESDYN_TILE_BLOCK=$BEST timeout 40 "${fit[@]}" --iterations 20 --fused --tiles --json $R/warmup.json > $R/warmup.log 2>&1
stage "warmup rc=$?"
timeout 55 "${fit[@]}" --iterations 2000 --fused --json $R/fused.json > $R/fused.log 2>&1; stage "fused rc=$?"
timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/tiles_m.json > $R/tiles_m.log 2>&1
stage "tiles default rc=$?"
if [ "$BEST" != 8x32x256 ] && [ $(( END - $(date +%s) )) -gt 40 ]; then
  WRESDYN_TILE_BLOCK=$BEST timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/tiles_best.json \
    > $R/tiles_best.log 2>&1; stage "tiles best rc=$?"
fi
python3 .dev/next3/summary.py $R > $R/summary.txt 2>&1 || true
echo done > $R/DONE
