#!/usr/bin/env bash
# One H200, done by END: the tile kernels of the fused MLP step (GradFitConfig.network_tiles) and the rollout's
# observation node (WRESDYN_OBS_NODE=1) checked and timed:
#   a. tests.txt: their tests on cuda:0 (tests/learn/test_tile_mlp.py, tests/sim/test_observe.py) and the fit's
#      graph-replayed iteration against the eager one, with the node on;
#   b. warmup: 20 iterations with both (compiles their kernels, captures each window length once);
#   c. the 2000 iterations at 1024 windows (benchmarks/speed/gradfit_2000.py), each once: fused (the baseline),
#      fused + tiles + node, plain + node (its figures to compare with the plain path's recorded on two earlier H200s,
#      the same to the last digit there), then fused + tiles without the node while time is left.
# Usage (repository root of the slim tree, PYTHONPATH set; this script at .dev/job.sh, the tree's commit in
# .dev/COMMIT): bash .dev/job.sh END_EPOCH. Results in /root/res.
set -u
END=${1:?END epoch}
R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
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
  echo "tree: $(cat .dev/COMMIT)"; sha256sum data/dataset.npz; } > $R/machine.txt 2>&1
stage start
fit=(python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --windows 1024)
WRESDYN_OBS_NODE=1 leg tests.txt 230 110 python3 -m pytest -q -rA -p no:cacheprovider tests/learn/test_tile_mlp.py \
  tests/sim/test_observe.py tests/learn/test_learner_speed_paths.py::test_graph_replayed_fit_iteration_equals_the_eager_one
WRESDYN_OBS_NODE=1 leg warmup.log 180 50 "${fit[@]}" --iterations 20 --fused --tiles --json $R/warmup.json
WRESDYN_OBS_NODE=0 leg fused.log 120 55 "${fit[@]}" --iterations 2000 --fused --json $R/fused.json
WRESDYN_OBS_NODE=1 leg tiles_node.log 60 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/tiles_node.json
WRESDYN_OBS_NODE=1 leg plain_node.log 0 55 "${fit[@]}" --iterations 2000 --json $R/plain_node.json
WRESDYN_OBS_NODE=0 leg tiles.log 0 55 "${fit[@]}" --iterations 2000 --fused --tiles --json $R/tiles.json
python3 - $R > $R/summary.txt 2>&1 <<'PY'
import json, sys
from pathlib import Path
r = Path(sys.argv[1])
t = (r / "tests.txt").read_text().splitlines() if (r / "tests.txt").exists() else []
print("tests:", next((x for x in reversed(t) if " passed" in x or " failed" in x or "error" in x), "no summary"))
runs = {n: json.loads((r / f"{n}.json").read_text()) for n in ("fused", "tiles_node", "plain_node", "tiles")
        if (r / f"{n}.json").exists()}
for n, x in runs.items():
    print(f"{n}: train_s {x['train_s']:.2f}, final loss {x['final_loss']!r}, final validation {x['final_validation']!r}, "
          f"best {x['best_validation']!r} at {x['best_iteration']}")
plain = 0.03141096408435372  # the plain path's final validation on two earlier H200s (h200_20261201c, h200_20261201)
for n, x in runs.items():
    print(f"{n}: validation minus the plain path's {x['final_validation'] - plain:+.3e} rad")
PY
stage done
cat $R/summary.txt
