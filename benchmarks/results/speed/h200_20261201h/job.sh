#!/usr/bin/env bash
# One H200: the tile/layer kernel tests on CUDA, the step over the layer kernels' rows a thread against torch and the
# tiles, then the 2000 iterations at 1024 windows: torch fused, the layer kernels (fastest rows), the tiles, plain.
set -u
END=$1; R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
left() { echo $(( END - $(date +%s) )); }
{ date -u; nvidia-smi -L; python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"; \
  echo "tree: $(cat .dev/COMMIT)"; } > $R/machine.txt 2>&1
stage start
unset WRESDYN_TILE_BLOCK WRESDYN_LAYER_ROWS
timeout 150 python3 benchmarks/speed/tile_mlp_step.py --device cuda:0 --windows 1024 --blocks 8x32x256 \
  --layer-rows 1,2,4,8,16 --json $R/step.json > $R/step.txt 2>&1; stage "step rc=$?"
BEST=$(python3 - <<'P'
import json
d = json.load(open("/root/res/step.json"))
print(min(d["layers"], key=lambda t: t["graph_us_per_step"])["rows"])
P
)
BEST=${BEST:-8}; echo "$BEST" > $R/best.txt; stage "best rows $BEST"
fit=(python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --windows 1024)
export WRESDYN_LAYER_ROWS=$BEST
timeout 60 "${fit[@]}" --iterations 20 --fused --layers --json $R/warmup.json > $R/warmup.log 2>&1
stage "warmup rc=$?"
timeout 55 "${fit[@]}" --iterations 2000 --fused --json $R/fused.json > $R/fused.log 2>&1; stage "fused rc=$?"
timeout 55 "${fit[@]}" --iterations 2000 --fused --layers --json $R/layers.json > $R/layers.log 2>&1
stage "layers rc=$?"
timeout 150 python3 -m pytest -q -rA -p no:cacheprovider tests/learn/test_tile_mlp.py -k "cuda or graph" \
  > $R/tests.txt 2>&1; stage "tests rc=$?"
[ $(left) -gt 60 ] && { timeout 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/tiles.json \
  > $R/tiles.log 2>&1; stage "tiles rc=$?"; }
[ $(left) -gt 60 ] && { timeout 55 "${fit[@]}" --iterations 2000 --json $R/plain.json > $R/plain.log 2>&1; \
  stage "plain rc=$?"; }
python3 .dev/summary.py $R > $R/summary.txt 2>&1 || true
echo done > $R/DONE
