#!/bin/bash
# One GPU session's speed and floor measurements, in the order that keeps each clean, on a 2- or 4-GPU H200 host
# staged as the device README says (wheels installed under /tmp/site; this tree copied to a folder of its own, ignored
# data carried beside it). Stages, each only if named in STAGES (default: ppo coldfit gradfit floors55, in this order):
#   checks    the CUDA graph paths' CUDA tests, each file alone under a 300 s timeout, stopping at the first
#             failure and dumping every thread's stack after 120 s in one test (a hang shows where it waits):
#             tests/ppo/test_graph_update.py (one GPU, then two processes), tests/identify/test_sysid_graph.py,
#             tests/fit/test_fused_network.py;
#   ppo       the GPUs idle, nothing else on the host: three rounds of the packed update and the graph update (the
#             residual's default on CUDA), ITERS=50 BASELINE=0 GRAPH=1 benchmarks/speed/ppo90.sh (its own graph check
#             first), with FOUR=1 where four GPUs are visible;
#   coldfit   GPU 0 alone: the first fit from an empty Warp cache with the kernels the package ships, the same fit
#             again (warm), and warm with the identification stepped eagerly, the baseline (SHIPPED=1 NO_GRAPH=1
#             TOTAL=300 benchmarks/speed/coldfit.sh);
#   gradfit   GPU 1, beside coldfit (their compiles share the host's cores, stated in the output): the gradient fit's
#             2000 iterations, fused and plain (benchmarks/speed/gradfit10.sh, TOTAL 420 s: its first run compiles);
#   floors55  the uneven floor with the effort line search's corrections, one seed a GPU (RUNS55, default
#             "floor_unvp55_s2": seeds 0 and 1 ran in h200x2_20261130f): floor_fair_probe.sh with REUSE=1
#             BASE=floor_unvp NAME=floor_unvp55 KEEP="c_delta_action d_oracle e_randomized", then packed.
# The floors need SRC laid out as benchmarks/results/floor_fair/unvp55_choice/MANIFEST.md says (unvp55_fits/calibrated,
# unvp_fits/delta_action, floor_unvp_s2) and data/uneven_probe/dataset.npz; ppo and coldfit need data/dataset.npz.
#
#   STAGES="ppo coldfit gradfit floors55" bash benchmarks/speed/device_session.sh OUT [SRC]
#
# FLOOR_S (900) stops floors still running after that many seconds (SIGTERM; every policy checkpoints every 50
# iterations and the same command resumes). Writes OUT/STAGES (each stage's clock and host load), OUT/load.log (every
# 30 s: load, GPU use and memory), OUT/<stage>/ (each script's own output) and OUT/pack/ (the packed floors).
set -u
OUT=${1:?usage: device_session.sh OUT [SRC]}; SRC=${2:-}
STAGES=${STAGES-ppo coldfit gradfit floors55}
mkdir -p "$OUT"; OUT=$(cd "$OUT" && pwd)
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> "$OUT/STAGES"; }
has() { [[ " $STAGES " == *" $1 "* ]]; }
( while sleep 30; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi \
    --query-gpu=utilization.gpu,memory.used --format=csv,noheader | tr '\n' ' ')"; done ) >> "$OUT/load.log" 2>&1 &
LOAD=$!
trap 'kill $LOAD 2>/dev/null' EXIT
stage start "$STAGES"
check() {  # NAME FILE EXPR: one test file's CUDA tests (pytest -k EXPR)
  CUDA_VISIBLE_DEVICES=0,1 timeout 300 python3 -m pytest -p no:cacheprovider -x -s -rA -o faulthandler_timeout=120 \
    "$2" -k "$3" > "$OUT/checks/$1.txt" 2>&1
  local rc=$?; stage "check $1 rc=$rc"; return $rc
}

if has checks; then
  mkdir -p "$OUT/checks"
  check ppo_graph tests/ppo/test_graph_update.py cuda
  check sysid_graph tests/identify/test_sysid_graph.py on_cuda
  check fused_network tests/fit/test_fused_network.py graph_replayed
fi
if has ppo; then
  mkdir -p "$OUT/ppo"
  four=$(( $(nvidia-smi -L | wc -l) >= 4 ))
  ITERS=50 BASELINE=0 GRAPH=1 FOUR=$four bash benchmarks/speed/ppo90.sh "$OUT/ppo/ppo90" > "$OUT/ppo/ppo90.log" 2>&1
  stage "ppo rc=$?"
fi
pids=()
if has coldfit; then
  ( GPU=0 SHIPPED=1 NO_GRAPH=1 TOTAL=300 bash benchmarks/speed/coldfit.sh "$OUT/coldfit" > "$OUT/coldfit.log" 2>&1
    stage "coldfit rc=$?" ) &
  pids+=($!)
fi
if has gradfit; then
  sleep 5
  ( CUDA_VISIBLE_DEVICES=1 TOTAL=420 bash benchmarks/speed/gradfit10.sh "$OUT/gradfit" > "$OUT/gradfit.log" 2>&1
    stage "gradfit rc=$?" ) &
  pids+=($!)
fi
[ ${#pids[@]} -gt 0 ] && wait "${pids[@]}"
if has floors55; then
  [ -n "$SRC" ] || { echo "error: floors55 needs SRC" >&2; exit 2; }
  ( REUSE=1 BASE=floor_unvp NAME=floor_unvp55 KEEP="c_delta_action d_oracle e_randomized" \
      CAL=/root/unvp55_fits/calibrated GPUS="0 1" RUNS="${RUNS55:-floor_unvp55_s2}" \
      bash benchmarks/skills/floor_fair_probe.sh "$SRC" "$OUT/floors55" > "$OUT/floors55.log" 2>&1
    stage "floors55 rc=$?" ) &
  fl=$!; t=$(date +%s)
  while kill -0 $fl 2>/dev/null && [ $(( $(date +%s) - t )) -lt "${FLOOR_S:-900}" ]; do sleep 10; done
  if kill -0 $fl 2>/dev/null; then
    stage "floors55 stopped at ${FLOOR_S:-900} s"; pkill -TERM -f "[w]resdyn.cli deploy"; sleep 20
  fi
  wait $fl 2>/dev/null
  python3 benchmarks/skills/floor_fair_pack.py "$OUT/pack" /root > "$OUT/pack.log" 2>&1
  for d in "$OUT"/pack/floor_unv_s*; do [ -d "$d" ] && mv "$d" "${d/floor_unv_s/floor_unvp55_s}"; done
  stage packed
fi
stage done
