#!/bin/bash
# Resume the floor benchmark's six full-size runs (benchmarks/results/floor_fair/full/, MANIFEST.md) on a 2-GPU host:
# the three default-mismatch runs on GPU 0, the three uneven-mismatch runs on GPU 1, each one `wresdyn deploy --floor
# --full` process that reuses its finished policies, trains what is left and then deploys every policy on the
# validation and held-out motions (results.json, report.md, the held-out ledger).
#
#   bash benchmarks/skills/floor_fair_resume.sh SRC LOG
#
# SRC holds floor_def_s{0,1,2}, floor_unv_s{0,1,2} and unv_fits as committed; they are copied to /root/<name>, the
# absolute paths their skills' config.json files record (a resumed skill may change only its iterations, device and
# threads). data/uneven/dataset.npz must exist (`wresdyn collect --mismatch data/mismatch_uneven.toml --out
# data/uneven`, deterministic). LOG gets STAGES (each run's end, with the load average), <run>.out (each process's
# output) and load.log (load and GPU use every 30 s). Python is python3; the environment (PYTHONPATH, caches) is the
# caller's. Returns when all six have ended.
set -u
SRC=${1:?usage: floor_fair_resume.sh SRC LOG}; R=${2:?usage: floor_fair_resume.sh SRC LOG}
mkdir -p "$R"
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> "$R/STAGES"; }
[ -f data/uneven/dataset.npz ] || { echo "error: data/uneven/dataset.npz is missing: record it first" >&2; exit 2; }
for r in floor_def_s0 floor_def_s1 floor_def_s2 floor_unv_s0 floor_unv_s1 floor_unv_s2 unv_fits; do
  [ -d "$SRC/$r" ] || { echo "error: $SRC/$r is missing" >&2; exit 2; }
  [ -e /root/$r ] || cp -r "$SRC/$r" /root/$r
done
P="a_nominal b_calibrated c_delta_action d_oracle e_randomized f_calibrated_narrow"
floor() {  # GPU NAME SEED MISMATCH DATA [FLAGS]
  local g=$1 n=$2 s=$3 m=$4 d=$5; shift 5
  local t=$(date +%s)
  CUDA_VISIBLE_DEVICES=$g python3 -m wresdyn.cli deploy $d --floor --full --device cuda:0 --mismatch $m --seed $s \
    --nominal floor_nominal --policies $P --no-animation --quiet --out /root/$n "$@" >> "$R/$n.out" 2>&1
  stage floor $n rc=$? after $(( $(date +%s) - t )) s
}
DEF="data/mismatch_default.toml data/dataset.npz"
UNV="data/mismatch_uneven.toml data/uneven/dataset.npz"
CD="--calibrated /root/floor_def_s0/calibrated --delta /root/floor_def_s0/delta_action"
CU="--calibrated /root/unv_fits/calibrated --delta /root/unv_fits/delta_action"
stage floors start
( while sleep 30; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi --query-gpu=utilization.gpu,memory.used \
    --format=csv,noheader | tr '\n' ' ')"; done ) >> "$R/load.log" 2>&1 &
LOAD=$!
floor 0 floor_def_s0 0 $DEF &
floor 1 floor_unv_s0 0 $UNV $CU &
sleep 10; floor 0 floor_def_s1 1 $DEF $CD &
floor 1 floor_unv_s1 1 $UNV $CU &
sleep 10; floor 0 floor_def_s2 2 $DEF $CD &
floor 1 floor_unv_s2 2 $UNV $CU &
wait $(jobs -p | grep -v "^$LOAD$")
kill $LOAD 2>/dev/null
stage floors done
