#!/usr/bin/env bash
# One H200, done by END (legs <= 8 min in all): the fused MLP step's tile kernels with MathDx's GEMM
# (TileBlock.mathdx, WRESDYN_TILE_BLOCK=...m) checked and timed against Warp's tile GEMM and the torch fused path:
#   a. prebuilt.txt, ready.txt, ready_fwd.txt, ready_bwd.txt: the MathDx modules into Warp's cache. The sm_90 CUBINs
#      compiled ahead on a CPU host (prebuilt/tiles_sm90.tar.xz beside this script, benchmarks/speed/prebuild_tiles.py)
#      and the shipped replay kernels merged into one WRESDYN_PREBUILT_KERNELS folder, its index checked against this
#      host's module hashes; where an entry is missing or does not match, every module compiled here at once (JOBS
#      processes); then the forward and the backward modules loaded by two processes (each entry taken or compiled);
#   b. tests.txt: tests/learn/test_tile_mlp.py with WRESDYN_TILE_BLOCK=16x32x128m (its CUDA cases on cuda:0);
#   c. step.txt, step.json: benchmarks/speed/tile_mlp_step.py on cuda:0 at 1024 windows, µs a step replayed from a
#      CUDA graph: torch fused, Warp's GEMM at 16x32x128, MathDx at 16x32x128, 8x32x128, 16x32x256, 32x32x256;
#   d. warmup.log, fused.log, tiles_m.log (+ .json): the 2000 iterations at 1024 windows (gradfit_2000.py), --fused
#      and --fused --tiles with WRESDYN_TILE_BLOCK=$TILE (16x32x128m), after 20 warm-up iterations; summary.txt.
# Usage, from the repository root of the tree with PYTHONPATH set (nothing else running):
#   bash benchmarks/results/speed/gpu57_next3/job.sh $(( $(date +%s) + 480 ))
# Results in $RES (default /root/res). For a plumbing check on a CPU host: DEVICE (cuda:0), WINDOWS (1024), ITERS
# (2000), STEP_ARGS and FIT_ARGS (more arguments of tile_mlp_step.py, gradfit_2000.py), BLOCKS, TILE, TESTS, JOBS.
set -u
END=${1:?END epoch}
HERE=$(cd "$(dirname "$0")" && pwd)
R=${RES:-/root/res}; mkdir -p "$R"
DEVICE=${DEVICE:-cuda:0} WINDOWS=${WINDOWS:-1024} ITERS=${ITERS:-2000} STEP_ARGS=${STEP_ARGS:-} FIT_ARGS=${FIT_ARGS:-}
BLOCKS=${BLOCKS:-16x32x128,16x32x128m,8x32x128m,16x32x256m,32x32x256m}
TILE=${TILE:-16x32x128m}  # the default split, with MathDx's GEMM
TESTS=${TESTS:-tests/learn/test_tile_mlp.py}
JOBS=${JOBS:-10}  # every module at once: ~2.3 GB and one core each, ~2 min a module on the CPU host
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
# the fit's network at every MathDx block timed below, the tests' small network at the tests' block (the default)
pb=(python3 benchmarks/speed/prebuild_tiles.py "$PB")
# a. WRESDYN_PREBUILT_KERNELS replaces the shipped folder: both merged, so that the fit's replay kernels stay prebuilt
prebuilt() {
  rm -rf "$PB" "$PB.src" && mkdir -p "$PB.src" && "${pb[@]}" --merge wresdyn/sim/prebuilt_kernels || return
  if [ -f "$HERE/prebuilt/tiles_sm90.tar.xz" ]; then
    tar -xJf "$HERE/prebuilt/tiles_sm90.tar.xz" -C "$PB.src" && "${pb[@]}" --merge "$PB.src" || return
  fi
  "${pb[@]}" --check
}
leg prebuilt.txt 420 40 bash -c "$(declare -p pb PB HERE); $(declare -f prebuilt); prebuilt"
export WRESDYN_PREBUILT_KERNELS=$PB
ready() {  # compile what the folder lacks (every module at once), then both halves loaded at once
  local on=(); [[ $DEVICE == cuda* ]] && on=(--device "$DEVICE")  # the names this GPU loads (CUBIN or PTX)
  if ! "${pb[@]}" --check "${on[@]}"; then echo "compiling here"; "${pb[@]}" --jobs "$JOBS" "${on[@]}" || return; fi
  "${pb[@]}" --load "$DEVICE" --which 0 > "$R/ready_fwd.txt" 2>&1 &
  "${pb[@]}" --load "$DEVICE" --which 1 > "$R/ready_bwd.txt" 2>&1; local a=$?
  wait $!; return $(( a | $? ))
}
leg ready.txt 300 200 bash -c "$(declare -p pb R DEVICE JOBS); $(declare -f ready); ready"
# b. the tests with MathDx's GEMM
WRESDYN_TILE_BLOCK=16x32x128m leg tests.txt 210 100 python3 -m pytest -q -rA -p no:cacheprovider $TESTS
# c. the block shapes, µs a step replayed from a CUDA graph
leg step.txt 150 60 python3 benchmarks/speed/tile_mlp_step.py --device "$DEVICE" --windows "$WINDOWS" \
  --blocks "$BLOCKS" --json "$R/step.json" $STEP_ARGS
# d. the 2000 iterations: the torch fused path, then the tiles with MathDx's GEMM
fit=(python3 benchmarks/speed/gradfit_2000.py --device "$DEVICE" --windows "$WINDOWS" $FIT_ARGS)
WRESDYN_TILE_BLOCK=$TILE leg warmup.log 120 30 "${fit[@]}" --iterations 20 --fused --tiles --json "$R/warmup.json"
leg fused.log 60 55 "${fit[@]}" --iterations "$ITERS" --fused --json "$R/fused.json"
WRESDYN_TILE_BLOCK=$TILE leg tiles_m.log 0 55 "${fit[@]}" --iterations "$ITERS" --fused --tiles \
  --json "$R/tiles_m.json"
timeout 30 python3 "$HERE/summary.py" "$R" > "$R/summary.txt" 2>&1
stage done
cat "$R/summary.txt"
