#!/usr/bin/env bash
# A first GPU fit's seconds on a fresh machine, four whole commands in one go (each timed by the shell, its log kept,
# every fit line stamped with the seconds since its process started: WRESDYN_LOG_CLOCK=1, so the log says when the
# first iteration was done):
#   a. fit_cold:      `wresdyn fit DATA --device DEV --eval` from an empty Warp cache, no prebuilt kernels (the
#                     baseline of this run);
#   b. warmup_export: `wresdyn warmup --device DEV --no-shipped --robot ROBOT --export OUT/prebuilt` from another
#                     empty cache (the dataset's robot only: the kernels the fit loads; the shipped SO-101's would add
#                     about a minute and the fit does not use them);
#   c. fit_prebuilt:  the fit from a third empty cache with WRESDYN_PREBUILT_KERNELS=OUT/prebuilt (the cold figure a
#                     user of a package with shipped kernels sees);
#   d. fit_warm:      the same command again on c's cache;
#   e. fit_warm_graph (only with STEP_GRAPH=1): d again with `--identify.cuda-graph True` (identification's Adam step
#                     replayed from a CUDA graph, SysIdConfig.cuda_graph), on the same cache; the default on CUDA
#                     since the graph was measured, so e repeats d there (NO_GRAPH=1 gives d's eager baseline).
# CUDA's own cache is off (CUDA_CACHE_DISABLE=1) and each step has its own WARP_CACHE_PATH under OUT, so nothing
# compiled by one step serves another except through the export; the background compile a cold fit leaves running
# for its next run (the one-kernel adjoint) is ended after the step (OUT/STAGES says how many), so no step shares the
# host with another's compiler. Run from the repository root on an idle GPU (no
# other work on it), the environment set by the caller (PYTHONPATH etc.):
#
#   bash benchmarks/speed/coldfit.sh OUT
#
# Environment: PYTHON (python3), DEVICE (cuda:0), DATA (data/dataset.npz), ROBOT (scenes/humanoid.usda, the
# dataset's), FIT_EXTRA (more fit arguments, none by default; a CPU smoke check: DEVICE=cpu FIT_EXTRA="--iterations 4
# --identify.iterations 4 --windows 4"), TOTAL (the whole script's budget [s], 355: each step gets what is left, a
# step cut short says so: rc=124; with STEP_GRAPH=1 give it about 80 s more), GPU (the CUDA_VISIBLE_DEVICES of every
# step, 0), STEP_GRAPH (1: run step e), NO_GRAPH (1: d again with `--identify.cuda-graph False`, fit_warm_eager: the
# identification stepped eagerly, the baseline of a default that replays its graph), SHIPPED (1: skip a and b; c
# from an empty cache with the kernels the package ships, WRESDYN_PREBUILT_KERNELS unset: ~3 min for c, d and one more),
# HELPER_PAIRS (N: after d, N pairs of d again, alternating, fit_warm_h0_I with WRESDYN_FIT_HELPERS=0, the tail in
# one process, and fit_warm_hx_I with the helper processes of wresdyn.cli.fit.helper_count; about 55 s a step on an
# H200: raise TOTAL).
# Output: OUT/<step>.log (stdout and stderr, its last line `whole command: S s rc=RC`), OUT/<step>.fitlog (the run's
# fit.log), OUT/STAGES (the clock of each step), OUT/machine.txt, OUT/summary.txt (each step's whole command and
# first-iteration times, read off the logs).
set -uo pipefail
out=${1:?usage: coldfit.sh OUT}
mkdir -p "$out"
out=$(cd "$out" && pwd)
py=${PYTHON:-python3}
dev=${DEVICE:-cuda:0}
data=${DATA:-data/dataset.npz}
robot=${ROBOT:-scenes/humanoid.usda}
extra=${FIT_EXTRA:-}
total=${TOTAL:-355}
export CUDA_VISIBLE_DEVICES=${GPU:-0} CUDA_CACHE_DISABLE=1 PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 WRESDYN_LOG_CLOCK=1
unset WRESDYN_PREBUILT_KERNELS WRESDYN_FIT_HELPERS
t_start=$(date +%s)
stage() { echo "$(date -u +%T) $*" >> "$out/STAGES"; }
left() { echo $(( total - ($(date +%s) - t_start) )); }

bash "$(dirname "$0")/machine_info.sh" "$py" > "$out/machine.txt"

timed() {  # timed STEP CMD...: the whole command under the budget left, its log and the shell's clock
  local step=$1; shift
  local budget; budget=$(left)
  if [ "$budget" -le 5 ]; then
    echo "not run: the budget of $total s is spent" > "$out/$step.log"; stage "$step skipped"; return
  fi
  stage "$step start"
  local s; s=$(date +%s.%N)
  timeout "$budget" "$@" > "$out/$step.log" 2>&1
  local rc=$?
  echo "whole command: $("$py" -c "import time; print(round(time.time() - $s, 1))") s rc=$rc" >> "$out/$step.log"
  stage "$step rc=$rc"
}

workers() {  # workers CACHE: pids of the background compile workers writing into that Warp cache
  ps -eo pid=,comm=,args= | awk -v c="$1/" '$2 ~ /^python/ && index($0, "compile_worker.py") && index($0, c) {print $1}'
}

fit() {  # fit STEP CACHE [MORE...]: the fit from that Warp cache folder, with more arguments
  local step=$1 cache=$2; shift 2
  rm -rf "$out/runs/$step"
  WARP_CACHE_PATH=$cache timed "$step" "$py" -m wresdyn.cli fit "$data" --device "$dev" --eval --out "$out/runs/$step" \
    $extra "$@"
  set -- "$step" "$cache"
  cp "$out/runs/$1/fit.log" "$out/$1.fitlog" 2>/dev/null
  # a cold CUDA fit leaves the one-kernel adjoint compiling for the next run in a detached worker (the command does
  # not wait for it): ended here, by pid, so that it takes no cores from the next step's clock
  local pids; pids=$(workers "$2")
  stage "$1 left $(echo $pids | wc -w) background compile worker(s)${pids:+, ended: $pids}"
  [ -n "$pids" ] && kill $pids 2>/dev/null
}

: > "$out/STAGES"
rm -rf "$out/wc_cold" "$out/wc_export" "$out/wc_prebuilt" "$out/prebuilt"
if [ "${SHIPPED:-0}" = 1 ]; then
  # the package's own prebuilt kernels (wresdyn/sim/prebuilt_kernels), as a user's first run finds them
  fit fit_prebuilt "$out/wc_prebuilt"
  steps="fit_prebuilt"
else
  fit fit_cold "$out/wc_cold"
  WARP_CACHE_PATH=$out/wc_export timed warmup_export "$py" -m wresdyn.cli warmup --device "$dev" --no-shipped \
    --robot "$robot" --export "$out/prebuilt"
  du -sh "$out/prebuilt" >> "$out/warmup_export.log" 2>&1
  export WRESDYN_PREBUILT_KERNELS=$out/prebuilt
  fit fit_prebuilt "$out/wc_prebuilt"
  steps="fit_cold warmup_export fit_prebuilt"
fi
fit fit_warm "$out/wc_prebuilt"
steps="$steps fit_warm"
if [ "${STEP_GRAPH:-0}" = 1 ]; then
  fit fit_warm_graph "$out/wc_prebuilt" --identify.cuda-graph True
  steps="$steps fit_warm_graph"
fi
if [ "${NO_GRAPH:-0}" = 1 ]; then
  fit fit_warm_eager "$out/wc_prebuilt" --identify.cuda-graph False
  steps="$steps fit_warm_eager"
fi
for i in $(seq 1 "${HELPER_PAIRS:-0}"); do
  # d again, alternating: the fit's tail in this process (WRESDYN_FIT_HELPERS=0) and in its helper processes (the
  # rule of wresdyn.cli.fit.helper_count: three from 8 cores)
  WRESDYN_FIT_HELPERS=0 fit "fit_warm_h0_$i" "$out/wc_prebuilt"
  fit "fit_warm_hx_$i" "$out/wc_prebuilt"
  steps="$steps fit_warm_h0_$i fit_warm_hx_$i"
done

for step in $steps; do
  whole=$(grep -h "^whole command:" "$out/$step.log" 2>/dev/null | tail -1)
  first=$(grep -ho "first iteration of [a-z]* done at [0-9.]* s" "$out/$step.log" 2>/dev/null | head -1)
  echo "$step: ${whole:-not run}${first:+; $first}"
done > "$out/summary.txt"
cat "$out/summary.txt"
