#!/usr/bin/env bash
# One H200, done by END (legs <= 8 min in all): the fused MLP step's tile kernels with MathDx's GEMM
# (TileBlock.mathdx, WRESDYN_TILE_BLOCK=...m) checked and timed against Warp's tile GEMM and the torch fused path:
#   a. prebuilt.txt, ready.txt, ready_fwd.txt, ready_bwd.txt: the MathDx modules into Warp's cache. prebuilt/ beside
#      this script (sm_90 CUBINs compiled ahead on a CPU host by benchmarks/speed/prebuild_tiles.py) and the shipped
#      replay kernels merged into one WRESDYN_PREBUILT_KERNELS folder, its index checked against this host's module
#      hashes, then the forward and the backward modules loaded by two processes at once (each taken from the folder,
#      else compiled here, ~2 min a MathDx module on one core);
#   b. tests.txt: tests/learn/test_tile_mlp.py with WRESDYN_TILE_BLOCK=16x32x128m (its CUDA cases on cuda:0);
#   c. step.txt, step.json: benchmarks/speed/tile_mlp_step.py on cuda:0 at 1024 windows, µs a step replayed from a
#      CUDA graph: torch fused, Warp's GEMM at 16x32x128, MathDx at 16x32x128, 8x32x128, 16x32x256, 32x32x256;
#   d. warmup.log, fused.log, tiles_m.log (+ .json): the 2000 iterations at 1024 windows (gradfit_2000.py), --fused
#      and --fused --tiles with WRESDYN_TILE_BLOCK=$TILE (16x32x128m), after 20 warm-up iterations; summary.txt.
# Usage, from the repository root of the tree with PYTHONPATH set:
#   bash benchmarks/results/speed/gpu57_next3/job.sh $(( $(date +%s) + 500 ))
# Results in $RES (default /root/res). For a plumbing check on a CPU host: DEVICE (cuda:0), WINDOWS (1024), ITERS
# (2000), STEP_ARGS and FIT_ARGS (more arguments of tile_mlp_step.py, gradfit_2000.py), BLOCKS, TILE, TESTS.
set -u
END=${1:?END epoch}
HERE=$(cd "$(dirname "$0")" && pwd)
R=${RES:-/root/res}; mkdir -p "$R"
DEVICE=${DEVICE:-cuda:0} WINDOWS=${WINDOWS:-1024} ITERS=${ITERS:-2000} STEP_ARGS=${STEP_ARGS:-} FIT_ARGS=${FIT_ARGS:-}
BLOCKS=${BLOCKS:-16x32x128,16x32x128m,8x32x128m,16x32x256m,32x32x256m}
TILE=${TILE:-16x32x128m}  # the default split, with MathDx's GEMM
TESTS=${TESTS:-tests/learn/test_tile_mlp.py}
PB=${PB:-/tmp/prebuilt_tiles}
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> "$R/STAGES"; }
leg() {  # leg NAME RESERVE CAP CMD...: CMD under timeout min(CAP, left before END - RESERVE)
  local name=$1 reserve=$2 cap=$3; shift 3
  local budget=$(( END - $(date +%s) - reserve ))
  [ "$budget" -gt "$cap" ] && budget=$cap
  [ "$budget" -le 5 ] && { stage "$name not run"; return; }
  timeout "$budget" "$@" > "$R/$name" 2>&1
  stage "$name rc=$? (cap $budget s)"
}
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; uptime
  python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"
  echo "tree: $(git rev-parse HEAD 2>/dev/null || cat .dev/COMMIT 2>/dev/null)"; sha256sum data/dataset.npz; } \
  > "$R/machine.txt" 2>&1
stage start
pb=(python3 benchmarks/speed/prebuild_tiles.py "$PB")
# the fit's network at every MathDx block timed below, the tests' small network at the tests' block
nets=("--widths 84,256,128,64,21 --blocks 16x32x128m,8x32x128m,16x32x256m,32x32x256m"
      "--widths 84,32,32,21 --blocks 16x32x128m")
# a. WRESDYN_PREBUILT_KERNELS replaces the shipped folder: merge both, so that the fit's replay kernels stay prebuilt
{ rm -rf "$PB" && "${pb[@]}" --merge wresdyn/sim/prebuilt_kernels \
  && if [ -d "$HERE/prebuilt" ]; then "${pb[@]}" --merge "$HERE/prebuilt"; fi
  for n in "${nets[@]}"; do timeout 60 "${pb[@]}" $n --check; echo "check rc=$?"; done
} > "$R/prebuilt.txt" 2>&1
export WRESDYN_PREBUILT_KERNELS=$PB
ready() {  # ready WHICH: every net's modules of one half (0 forward, 1 backward) loaded on the device
  for n in "${nets[@]}"; do "${pb[@]}" $n --load "$DEVICE" --which "$1" || return; done
}
leg ready.txt 330 120 bash -c "$(declare -p pb nets DEVICE R); $(declare -f ready); ready 0 > \"\$R/ready_fwd.txt\" 2>&1 &
  ready 1 > \"\$R/ready_bwd.txt\" 2>&1; a=\$?; wait \$!; b=\$?; exit \$(( a | b ))"
# b. the tests with MathDx's GEMM
WRESDYN_TILE_BLOCK=16x32x128m leg tests.txt 210 120 python3 -m pytest -q -rA -p no:cacheprovider $TESTS
# c. the block shapes, µs a step replayed from a CUDA graph
leg step.txt 150 60 python3 benchmarks/speed/tile_mlp_step.py --device "$DEVICE" --windows "$WINDOWS" \
  --blocks "$BLOCKS" --json "$R/step.json" $STEP_ARGS
# d. the 2000 iterations: the torch fused path, then the tiles with MathDx's GEMM
fit=(python3 benchmarks/speed/gradfit_2000.py --device "$DEVICE" --windows "$WINDOWS" $FIT_ARGS)
WRESDYN_TILE_BLOCK=$TILE leg warmup.log 120 30 "${fit[@]}" --iterations 20 --fused --tiles --json "$R/warmup.json"
leg fused.log 60 55 "${fit[@]}" --iterations "$ITERS" --fused --json "$R/fused.json"
WRESDYN_TILE_BLOCK=$TILE leg tiles_m.log 0 55 "${fit[@]}" --iterations "$ITERS" --fused --tiles \
  --json "$R/tiles_m.json"
python3 "$HERE/summary.py" "$R" > "$R/summary.txt" 2>&1
stage done
cat "$R/summary.txt"
