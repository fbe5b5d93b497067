#!/bin/bash
# The residual PPO's scaling on 2 GPUs, three rounds, with rsl-rl's own update as the baseline in the same run:
#
#   bash benchmarks/speed/ppo90.sh OUT           # ~5 min on an idle 2-GPU host
#   BASELINE=0 bash benchmarks/speed/ppo90.sh OUT  # the default update only (~3.5 min)
#   ITERS=50 BASELINE=0 GRAPH=1 bash benchmarks/speed/ppo90.sh OUT  # the packed and the CUDA-graph update (~6 min)
#   DEVICE=cpu N=16 ITERS=1 bash benchmarks/speed/ppo90.sh OUT  # a check of the script on the CPU (gloo; no figure)
#   FOUR=1 ...                     # each round also on four GPUs (0-3), 4096 worlds each (a 4-GPU host)
#   VARIANTS="+graph +graph+pin +graph+defer_log +graph+pin+defer_log" bash benchmarks/speed/ppo90.sh OUT
#                                  # these case options side by side instead of BASELINE's and GRAPH's (~9 min)
#
# Each round: one GPU (torchrun, 1 process) at 4096 worlds, then two GPUs (torchrun, 2 processes) at 4096 worlds
# each, 2 untimed and 15 timed iterations per case (benchmarks/speed/ppo_scaling.py): the packed update run eagerly
# (+packed: wresdyn.ppo.packed_update.PackedPPO, ppo.graph_update false) and, unless BASELINE=0, rsl-rl's own
# PPO.update (+rsl_update), the same update bit for bit (tests/ppo/test_packed_update.py), and with GRAPH=1 the
# update replayed from one CUDA graph per mini-batch (+graph, ppo.graph_update: wresdyn.ppo.graph_update.GraphPPO,
# the residual's default on CUDA since these rounds measured it), in one process per launch, their order rotated
# from round to round so that none always runs first. VARIANTS (space-separated case options of
# benchmarks/speed/ppo_scaling.py, e.g. +pin: each process bound to its GPU's cores; +defer_log: no host wait per
# rollout step for rsl-rl's episode logging) replaces that list, rotated the same way. A list with +graph (GRAPH=1,
# or a VARIANTS entry) first checks the captured update against the packed
# one on one GPU and on two over NCCL (tests/ppo/test_graph_update.py's CUDA tests, where pytest is installed). Then
# the update's profile on 2 GPUs once (the packed update: the profile's synchronisations cannot run inside a
# capture).
# The environment (PYTHONPATH, caches) is the caller's; python is python3. Writes into OUT:
#   machine.txt                 the GPUs, host, load, versions, commit
#   one_rN.{txt,json}           round N on one GPU; two_rN.{txt,json} on two (four_rN with FOUR=1); table_rN.txt
#                               all of them with the efficiency
#   graph_check.txt             GRAPH=1: the CUDA test's output
#   profile_two.{txt,json}      benchmarks/speed/ppo_update_profile.py on 2 GPUs
#   steps.txt                   each step's start, seconds and exit status
set -u
OUT=${1:?usage: ppo90.sh OUT}
BASELINE=${BASELINE:-1} GRAPH=${GRAPH:-0} FOUR=${FOUR:-0} DEVICE=${DEVICE:-cuda} N=${N:-4096} ITERS=${ITERS:-15}
VARIANTS=${VARIANTS:-}
mkdir -p "$OUT"
PY=python3
TORCHRUN=(python3 -m torch.distributed.run --standalone)
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} PYTHONUNBUFFERED=1
HERE=$(cd "$(dirname "$0")/../.." && pwd)
cd "$HERE" || exit 1

FAILED=0
step() {  # step NAME COMMAND...: run it, log its time and status (a failed step does not stop the others)
  local name=$1 s e rc
  shift
  s=$(date +%s.%N)
  "$@"
  rc=$?
  (( rc == 0 )) || FAILED=$((FAILED + 1))
  e=$(date +%s.%N)
  echo "$(date -u +%T) $name: $(python3 -c "print(round($e - $s, 1))") s rc=$rc" | tee -a "$OUT/steps.txt"
}

{ date -u; nvidia-smi; nproc; lscpu | grep "Model name"; uptime
  $PY -c "import torch, warp, rsl_rl; from importlib.metadata import version
print('torch', torch.__version__, 'warp', warp.__version__, 'rsl-rl', version('rsl-rl-lib'))"
  git log -1 --format='%H %s' 2>/dev/null; git status --short 2>/dev/null | head -20; env | grep '^NCCL_' ; } \
  > "$OUT/machine.txt" 2>&1

scaling() {  # scaling GPUS PROCESSES JSON CASES...: ppo_scaling.py under torchrun, its output beside the JSON
  local gpus=$1 n=$2 json=$3
  shift 3
  CUDA_VISIBLE_DEVICES=$gpus "${TORCHRUN[@]}" --nproc_per_node "$n" benchmarks/speed/ppo_scaling.py --device "$DEVICE" \
    --iterations "$ITERS" --json "$json" --cases "$@" > "${json%.json}.txt" 2>&1
}

graph_check() {  # the captured update against the default one on GPU 0 and on GPUs 0-1, within its tolerance
  if ! $PY -c "import pytest" 2>/dev/null; then
    echo "pytest is not installed: no check" > "$OUT/graph_check.txt"
    return 0
  fi
  CUDA_VISIBLE_DEVICES=0,1 $PY -m pytest -p no:cacheprovider -q tests/ppo/test_graph_update.py -k cuda \
    > "$OUT/graph_check.txt" 2>&1
}
variants=("+packed")  # each case's options: the packed update, then the switched-on comparisons
[[ $BASELINE == 1 ]] && variants+=("+rsl_update")
[[ $GRAPH == 1 ]] && variants+=("+graph")
if [[ -n $VARIANTS ]]; then read -r -a variants <<< "$VARIANTS"; fi
graphed=0
for v in "${variants[@]}"; do [[ $v == *+graph* ]] && graphed=1; done
if [[ $graphed == 1 && $DEVICE == cuda* ]]; then step "graph check, 1 GPU" graph_check; fi
for r in 1 2 3; do
  k=$(( (r - 1) % ${#variants[@]} ))
  one=() two=() four=()
  for v in "${variants[@]:k}" "${variants[@]:0:k}"; do
    one+=("residual:$N$v") two+=("residual:$((2 * N))$v") four+=("residual:$((4 * N))$v")
  done
  step "round $r, 1 GPU: ${one[*]}" scaling 0 1 "$OUT/one_r$r.json" "${one[@]}"
  step "round $r, 2 GPUs: ${two[*]}" scaling 0,1 2 "$OUT/two_r$r.json" "${two[@]}"
  jsons=("$OUT/one_r$r.json" "$OUT/two_r$r.json")
  if [[ $FOUR == 1 ]]; then
    step "round $r, 4 GPUs: ${four[*]}" scaling 0,1,2,3 4 "$OUT/four_r$r.json" "${four[@]}"
    jsons+=("$OUT/four_r$r.json")
  fi
  $PY benchmarks/speed/ppo_scaling.py --table "${jsons[@]}" > "$OUT/table_r$r.txt" 2>&1
  cat "$OUT/table_r$r.txt"
done

profile() {
  CUDA_VISIBLE_DEVICES=0,1 "${TORCHRUN[@]}" --nproc_per_node 2 benchmarks/speed/ppo_update_profile.py --device "$DEVICE" \
    --envs $((2 * N)) --iterations "$(( ITERS < 5 ? ITERS : 5 ))" --json "$OUT/profile_two.json" > "$OUT/profile_two.txt" 2>&1
}
step "profile, 2 GPUs" profile
tail -n 20 "$OUT/profile_two.txt"
uptime >> "$OUT/machine.txt"
(( FAILED == 0 )) || { echo "ppo90.sh: $FAILED step(s) failed (steps.txt; each step's .txt)" >&2; exit 1; }
