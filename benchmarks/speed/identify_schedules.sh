#!/usr/bin/env bash
# Identification schedules for the GPU, chosen on validation: the default fit's command with other identification
# settings, each a whole `wresdyn fit DATA --device cuda:0` timed by the shell (WRESDYN_LOG_CLOCK=1 stamps its lines),
# then scored on the validation split only (`wresdyn eval RUN --splits validation`; held-out and OOD are not
# replayed: the choice is made on validation). The baseline, in the same run, is the default command with `--eval`
# (the figure the targets name; its held-out is the default configuration's, reported already). Two GPUs, three runs
# each, one after the other on its GPU; each GPU has its own Warp cache, filled from the shipped prebuilt kernels.
#
#   bash benchmarks/speed/identify_schedules.sh OUT     # ~5 min on an idle 2-GPU host
#
# Runs (GPU 0 / GPU 1); the identification's CUDA graph is named in every run, eager where not said (the default
# on CUDA is the graph since this script measured it; base is the default command of the tree it measured):
#   base          --eval                                       | w128     --identify.windows 128
#   graph         --identify.cuda-graph True                   | w128lr   --identify.windows 128 --identify.lr 0.02
#   w128lr_graph  w128lr with --identify.cuda-graph True       | w256lr   --identify.windows 256 --identify.lr 0.02
# Environment: PYTHON (python3), DATA (data/dataset.npz), DEVICE (cpu for a smoke check of the script, with
# FIT_EXTRA="--iterations 2 --identify.iterations 2 --windows 4"), FIT_EXTRA (more arguments for every fit), GPUS
# ("0 1"). Output: OUT/<run>.log (the command's output, last line `whole command: S s rc=RC`), OUT/<run>.val.json
# (the validation split's metrics), OUT/STAGES, OUT/machine.txt, OUT/table.txt (one line a run: whole command,
# first iteration, identification iterations, validation mean |dq| of PD + residual).
set -uo pipefail
out=${1:?usage: identify_schedules.sh OUT}
mkdir -p "$out"; out=$(cd "$out" && pwd)
py=${PYTHON:-python3}; data=${DATA:-data/dataset.npz}; extra=${FIT_EXTRA:-}; dev=${DEVICE:-cuda:0}
read -r -a gpus <<< "${GPUS:-0 1}"
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1 WRESDYN_LOG_CLOCK=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> "$out/STAGES"; }
bash "$(dirname "$0")/machine_info.sh" "$py" > "$out/machine.txt"

one() {  # one GPU NAME [ARGS...]: a whole fit, then its validation score
  local gpu=$1 name=$2; shift 2
  local run=$out/runs/$name; rm -rf "$run"
  stage "$name start (GPU $gpu)"
  local s; s=$(date +%s.%N)
  CUDA_VISIBLE_DEVICES=$gpu WARP_CACHE_PATH=$out/wc_$gpu "$py" -m wresdyn.cli fit "$data" --device "$dev" --out "$run" \
    --identify.cuda-graph False $extra "$@" > "$out/$name.log" 2>&1
  local rc=$?
  echo "whole command: $("$py" -c "import time; print(round(time.time() - $s, 1))") s rc=$rc" >> "$out/$name.log"
  stage "$name rc=$rc"
  CUDA_VISIBLE_DEVICES=$gpu WARP_CACHE_PATH=$out/wc_$gpu "$py" -m wresdyn.cli eval "$run" --splits validation \
    --device "$dev" --out "$run/val" > "$out/$name.val.log" 2>&1 && cp "$run/val/metrics.json" "$out/$name.val.json"
}

( one "${gpus[0]}" base --eval; one "${gpus[0]}" graph --identify.cuda-graph True
  one "${gpus[0]}" w128lr_graph --identify.windows 128 --identify.lr 0.02 --identify.cuda-graph True ) &
a=$!
sleep 3
( one "${gpus[1]:-${gpus[0]}}" w128 --identify.windows 128
  one "${gpus[1]:-${gpus[0]}}" w128lr --identify.windows 128 --identify.lr 0.02
  one "${gpus[1]:-${gpus[0]}}" w256lr --identify.windows 256 --identify.lr 0.02 ) &
b=$!
wait $a $b
"$py" - "$out" > "$out/table.txt" <<'PY'
import json, re, sys
from pathlib import Path
out = Path(sys.argv[1])
for name in ("base", "graph", "w128lr_graph", "w128", "w128lr", "w256lr"):
    log = out / f"{name}.log"
    text = log.read_text() if log.exists() else ""
    whole = re.findall(r"whole command: ([0-9.]+) s rc=(\d+)", text)
    first = re.findall(r"first iteration of identify done at ([0-9.]+) s", text)
    conv = re.findall(r"identification: converged at iteration (\d+)", text)
    val = out / f"{name}.val.json"
    v = json.loads(val.read_text())["splits"]["validation"]["pd_residual"]["mean_abs_dq"] if val.exists() else None
    print(f"{name:14s} whole {whole[-1][0] if whole else '-':>6s} s rc={whole[-1][1] if whole else '-'}  first iteration "
          f"{first[0] if first else '-':>5s} s  identification iterations {conv[0] if conv else '-':>5s}  "
          f"validation {'-' if v is None else f'{v:.6f}'} rad")
PY
cat "$out/table.txt"
