#!/usr/bin/env bash
# The fused MLP step's Warp tile kernels (GradFitConfig.network_tiles) on one GPU, in one go, done by END:
#   a. tests: tests/learn/test_tile_mlp.py (CPU and cuda:0, the graph-replayed fit with tiles against the fused one)
#      and tests/learn/test_fused_mlp.py;
#   b. one step, forward + backward, torch fused against tiles (benchmarks/speed/tile_mlp_step.py, 1024 windows,
#      H = 64, eager and replayed from a CUDA graph; TileBlock's default 8x32x256 and three other splits);
#   c. the gradient fit's 2000 iterations at 1024 windows (benchmarks/speed/gradfit_2000.py): a short warm-up run with
#      tiles (loads or compiles the kernels, captures every window length once), then `--fused` and
#      `--fused --tiles` once each; training seconds and the final and best validation of both.
# Every leg runs under `timeout`, capped by what is left before END less what the later legs need (280 s in all).
#
#   bash benchmarks/speed/gpu_tiles_job.sh END      # END: epoch seconds, e.g. $(( $(date +%s) + 300 ))
#
# Run from anywhere; it runs in the repository root with PYTHONPATH set to it. Environment: PYTHON (python3),
# DEVICE (cuda:0), RES (the output folder, /root/res). Output in RES: tests.txt, tile_step.{txt,json},
# warmup.log, fused.{log,json}, tiles.{log,json}, summary.txt (also printed).
set -uo pipefail
end=${1:?usage: gpu_tiles_job.sh END_EPOCH_SECONDS}
cd "$(dirname "$0")/../.."
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
py=${PYTHON:-python3}
dev=${DEVICE:-cuda:0}
res=${RES:-/root/res}
mkdir -p "$res"

leg() {  # leg NAME RESERVE CAP CMD...: CMD under timeout min(CAP, left before END - RESERVE), output to RES/NAME
  local name=$1 reserve=$2 cap=$3; shift 3
  local budget=$(( end - $(date +%s) - reserve ))
  [ "$budget" -gt "$cap" ] && budget=$cap
  if [ "$budget" -le 5 ]; then
    echo "$name: not run, no time left before END" | tee "$res/$name"; return
  fi
  local t0; t0=$(date +%s)
  timeout "$budget" "$@" > "$res/$name" 2>&1
  local rc=$?
  echo "$name: rc=$rc in $(( $(date +%s) - t0 )) s (cap $budget s)" | tee -a "$res/$name"
}

fit=("$py" benchmarks/speed/gradfit_2000.py --device "$dev" --windows 1024)

{ nvidia-smi --query-gpu=name,driver_version --format=csv,noheader; git rev-parse --short HEAD
  "$py" -c "import torch, warp; print('torch', torch.__version__, 'warp', warp.__version__)"
} > "$res/machine.txt" 2>&1
leg tests.txt 205 75 "$py" -m pytest -q -rA -p no:cacheprovider tests/learn/test_tile_mlp.py \
  tests/learn/test_fused_mlp.py
leg tile_step.txt 160 45 "$py" benchmarks/speed/tile_mlp_step.py --device "$dev" --windows 1024 \
  --blocks 16x32x128,8x32x128,8x32x256,32x32x256 --json "$res/tile_step.json"
leg warmup.log 110 50 "${fit[@]}" --iterations 20 --fused --tiles --json "$res/warmup.json"
leg fused.log 55 55 "${fit[@]}" --iterations 2000 --fused --json "$res/fused.json"
leg tiles.log 0 55 "${fit[@]}" --iterations 2000 --fused --tiles --json "$res/tiles.json"

"$py" - "$res" > "$res/summary.txt" 2>&1 <<'EOF'
import json, sys
from pathlib import Path

res = Path(sys.argv[1])
tests = (res / "tests.txt").read_text().splitlines() if (res / "tests.txt").exists() else []
print("tests:", next((line for line in reversed(tests) if " passed" in line or " failed" in line), "no summary"))
if (res / "tile_step.json").exists():
    s = json.loads((res / "tile_step.json").read_text())
    for name, fig in [("torch fused", s["torch"])] + [(str(t["block"]), t) for t in s["tiles"]]:
        print(f"one step, {name}: graph {fig.get('graph_us_per_step', float('nan')):.1f} µs, eager "
              f"{fig['eager_us_per_step']:.1f} µs" + (f"; max |tiles - torch| {max(fig['max_abs_diff'].values()):.1e}"
                                                     if "max_abs_diff" in fig else ""))
runs = {n: json.loads((res / f"{n}.json").read_text()) for n in ("fused", "tiles") if (res / f"{n}.json").exists()}
for name, r in runs.items():
    print(f"{name}: train_s {r['train_s']:.2f}, final validation {r['final_validation']}, best validation "
          f"{r['best_validation']} at {r['best_iteration']}, final loss {r['final_loss']:.6e}")
if len(runs) == 2:
    f, t = runs["fused"], runs["tiles"]
    print(f"tiles against fused: {t['train_s'] - f['train_s']:+.2f} s; final loss relative "
          f"{abs(t['final_loss'] - f['final_loss']) / abs(f['final_loss']):.1e}")
EOF
cat "$res/summary.txt"
