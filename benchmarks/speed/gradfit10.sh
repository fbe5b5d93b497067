#!/usr/bin/env bash
# The gradient fit's whole fixed schedule (2000 iterations at 1024 windows, benchmarks/speed/gradfit_2000.py) on one
# GPU, the fused MLP path (GradFitConfig.fused_network, `--fused`) against the plain path, in one go:
#   a. fused_cold: the fused path, first run (loads and, on a fresh machine, compiles the Warp kernels; its seconds
#                  include that: not the figure to report);
#   b. fused:      the fused path again, warm: the figure;
#   c. plain:      the plain path (`--plain`; on the CPU the default), warm: the baseline of this run;
#   d. plain_sN:   the plain path with seed N for each N in EXTRA_SEEDS (none by default): how far another seed moves
#                  the same path's result, the scale against which the fused path's difference is read.
# Then summary.txt: each run's training seconds and ms/iteration per window length, and b against c (the loss after
# the last iteration, relative; the validation error after it and the best one [rad]; their difference must stay at
# float32 noise grown over 2000 iterations: the plan's bounds are 1e-3 relative and 1e-4 rad).
# Run from the repository root on an idle GPU, the environment set by the caller (PYTHONPATH etc.):
#
#   bash benchmarks/speed/gradfit10.sh OUT
#
# The budget is for a machine whose Warp kernels are cached (or prebuilt: WRESDYN_PREBUILT_KERNELS): from an empty
# cache the first run compiles them first (minutes, benchmarks/results/speed/coldfit_accounting.md), so on a fresh
# machine run `wresdyn warmup --device cuda:0` before it, or give TOTAL more.
#
# Environment: PYTHON (python3), DEVICE (cuda:0), DATA (data/dataset.npz), ITERATIONS (2000), WINDOWS (1024),
# TOTAL (the whole script's budget [s], 235: each run gets what is left; one cut short says so, rc=124),
# EXTRA_SEEDS (space-separated seeds for the runs d, none by default).
# Output: OUT/<run>.json (gradfit_2000.py's figures), OUT/<run>.log (its output, last line `whole command: S s rc=RC`),
# OUT/machine.txt, OUT/summary.txt.
set -uo pipefail
out=${1:?usage: gradfit10.sh OUT}
mkdir -p "$out"
out=$(cd "$out" && pwd)
py=${PYTHON:-python3}
dev=${DEVICE:-cuda:0}
data=${DATA:-data/dataset.npz}
iters=${ITERATIONS:-2000}
windows=${WINDOWS:-1024}
total=${TOTAL:-235}
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
t_start=$(date +%s)

bash "$(dirname "$0")/machine_info.sh" "$py" > "$out/machine.txt"

run() {  # run NAME [ARGS...]: gradfit_2000.py under the budget left, its log and the shell's clock
  local name=$1; shift
  local budget=$(( total - ($(date +%s) - t_start) ))
  if [ "$budget" -le 5 ]; then
    echo "not run: the budget of $total s is spent" > "$out/$name.log"; return
  fi
  local s; s=$(date +%s.%N)
  timeout "$budget" "$py" benchmarks/speed/gradfit_2000.py --device "$dev" --data "$data" --iterations "$iters" \
    --windows "$windows" --json "$out/$name.json" "$@" > "$out/$name.log" 2>&1
  local rc=$?
  echo "whole command: $("$py" -c "import time; print(round(time.time() - $s, 1))") s rc=$rc" >> "$out/$name.log"
}

run fused_cold --fused
run fused --fused
run plain --plain
for seed in ${EXTRA_SEEDS:-}; do run "plain_s$seed" --plain --seed "$seed"; done

"$py" - "$out" > "$out/summary.txt" 2>&1 <<'EOF'
import json, sys
from pathlib import Path

out = Path(sys.argv[1])
names = ["fused_cold", "fused", "plain"] + sorted(p.stem for p in out.glob("plain_s*.json"))
runs = {n: json.loads((out / f"{n}.json").read_text()) for n in names if (out / f"{n}.json").exists()}
for name, r in runs.items():
    rates = ", ".join(f"H={x['horizon']}: {x['ms_per_iteration']:.2f}" if x["ms_per_iteration"] is not None
                      else f"H={x['horizon']}: -" for x in r["per_length"])
    print(f"{name}: fused_network {r.get('fused_network')}, training {r['train_s']:.2f} s, overhead "
          f"{r['overhead_s']}, final loss {r['final_loss']:.6e}, validation after the last iteration "
          f"{r['final_validation']}, best {r['best_validation']} at {r['best_iteration']}; ms/iteration {rates}")
if "fused" in runs and "plain" in runs:
    f, p = runs["fused"], runs["plain"]
    print(f"fused against plain: training {f['train_s']:.2f} s against {p['train_s']:.2f} s "
          f"({f['train_s'] - p['train_s']:+.2f} s)")
    print(f"final loss relative difference {abs(f['final_loss'] - p['final_loss']) / abs(p['final_loss']):.2e} "
          "(bound 1e-3)")
    for key in ("final_validation", "best_validation"):
        if f[key] is not None and p[key] is not None:
            print(f"{key} difference {abs(f[key] - p[key]):.2e} rad (bound 1e-4)")
else:
    print("fused or plain missing: see their logs")
for name in (n for n in runs if n.startswith("plain_s") and "plain" in runs):
    s, p = runs[name], runs["plain"]
    parts = [f"final loss relative {abs(s['final_loss'] - p['final_loss']) / abs(p['final_loss']):.2e}"]
    parts += [f"{key} {abs(s[key] - p[key]):.2e} rad" for key in ("final_validation", "best_validation")
              if s[key] is not None and p[key] is not None]
    print(f"{name} against plain (another seed, the same path): " + ", ".join(parts))
EOF
cat "$out/summary.txt"
