#!/bin/bash
# The floor benchmark's uneven mismatch again, its stand corrections fitted from stand data recorded with the
# saturation probe (`wresdyn collect --mismatch data/mismatch_uneven.toml --probe-saturation 6 --out
# data/uneven_probe`, then `unvp_fits/`): three runs floor_unvp_s{0,1,2}, each one `wresdyn deploy --floor --full`
# process as in floor_fair_resume.sh, on the GPUs round robin. (a) is the shipped floor_nominal; (b)-(f) are all
# trained from it here: (b), (c) and (f) because their corrections changed, and (d) and (e), which do not use the
# corrections, because the floor_unv_s* ones cannot be carried over: each skill's config.json records the absolute
# path of the (a) it was fine-tuned from (/root/floor_unv_sN/skills/a_nominal), and a resume in another folder is
# refused on that field.
#
#   bash benchmarks/skills/floor_fair_probe.sh SRC LOG
#
# SRC holds unvp_fits (calibrated/ and delta_action/, fitted) and, to resume a stopped session, the floor_unvp_s*
# folders as packed (floor_fair_pack.py); they are copied to $ROOT/<name> (ROOT, default /root: the absolute paths the
# skills' config.json files record, so a resume must use the same). data/uneven_probe/dataset.npz must exist. GPUS
# (default: every GPU nvidia-smi lists) are the CUDA devices the runs take in turn, started STAGGER s apart (10).
# RUNS (default: all three) narrows the runs to some of them, e.g. RUNS=floor_unvp_s1; a run's seed is the number its
# name ends in, whatever the order. DRY=1 checks the inputs and prints the commands without copying or running anything.
# LOG gets STAGES, <run>.out and load.log as floor_fair_resume.sh writes them. Python is python3; the environment is the
# caller's. Returns when all three have ended; rerun the same command to resume (finished policies and deployments are
# reused).
#
# REUSE=1 keeps (d) and (e) of the committed uneven runs, which do not depend on the corrections, and trains only (b),
# (c) and (f): seed N runs in $ROOT/floor_unv_sN, the folder its (d) and (e) were trained in (the path their
# config.json files record), set up once from SRC/floor_unv_sN with (b), (c), (f) and the earlier results removed (a
# marker file, .probe_reuse, says it was; the held-out ledger keeps the earlier scoring's line and gets this one's).
# SRC/floor_unvp_sN, where present, is such a folder packed by an earlier session and is resumed instead. Pack the
# folders as usual and keep them as floor_unvp_sN.
set -u
[ $# -eq 2 ] || { echo "usage: floor_fair_probe.sh SRC LOG" >&2; exit 2; }
SRC=$1; R=$2
ROOT=${ROOT:-/root}
DATA=data/uneven_probe/dataset.npz
RUNS=${RUNS:-floor_unvp_s0 floor_unvp_s1 floor_unvp_s2}
fail() { echo "error: $*" >&2; exit 2; }
[ -d "$SRC" ] || fail "$SRC is not a folder"
[ -f $DATA ] || fail "$DATA is missing: record it first (wresdyn collect --mismatch data/mismatch_uneven.toml \
--probe-saturation 6 --out data/uneven_probe)"
for c in calibrated delta_action; do
  [ -f "$SRC/unvp_fits/$c/policy.pt" ] || fail "$SRC/unvp_fits/$c/policy.pt is missing: fit the corrections first"
done
if [ -z "${GPUS:-}" ]; then
  GPUS=$(nvidia-smi --query-gpu=index --format=csv,noheader 2>/dev/null | tr '\n' ' ')
  [ -n "$GPUS" ] || fail "no GPU found (nvidia-smi lists none); set GPUS to run anyway"
fi
read -r -a gpu <<< "$GPUS"
P="a_nominal b_calibrated c_delta_action d_oracle e_randomized f_calibrated_narrow"
CU="--calibrated $ROOT/unvp_fits/calibrated --delta $ROOT/unvp_fits/delta_action"
out_of() {  # NAME: the folder a run writes
  if [ "${REUSE:-0}" = 1 ]; then echo "$ROOT/${1/floor_unvp_/floor_unv_}"; else echo "$ROOT/$1"; fi
}
command_of() {  # NAME SEED
  echo "python3 -m wresdyn.cli deploy $DATA --floor --full --device cuda:0 --mismatch data/mismatch_uneven.toml" \
    "--seed $2 --nominal floor_nominal --policies $P --no-animation --quiet --out $(out_of $1) $CU"
}
if [ "${REUSE:-0}" = 1 ]; then
  for n in $RUNS; do
    [ -d "$SRC/$n" ] || [ -d "$SRC/${n/floor_unvp_/floor_unv_}/skills/d_oracle" ] \
      || fail "REUSE=1 needs $SRC/${n/floor_unvp_/floor_unv_} (the committed run) or $SRC/$n"
  done
fi
if [ "${DRY:-0}" = 1 ]; then
  i=0
  for n in $RUNS; do
    echo "CUDA_VISIBLE_DEVICES=${gpu[$(( i % ${#gpu[@]} ))]} $(command_of $n ${n##*_s})"; i=$(( i + 1 ))
  done
  exit 0
fi
mkdir -p "$R"
mkdir -p "$ROOT"
[ -e "$ROOT/unvp_fits" ] || cp -r "$SRC/unvp_fits" "$ROOT/unvp_fits"
for r in $RUNS; do  # a run folder absent from SRC starts fresh in $ROOT
  o=$(out_of $r)
  [ -d "$SRC/$r" ] && [ ! -e "$o" ] && cp -r "$SRC/$r" "$o"
  if [ "${REUSE:-0}" = 1 ] && [ ! -e "$o/.probe_reuse" ]; then
    [ -e "$o" ] || cp -r "$SRC/${r/floor_unvp_/floor_unv_}" "$o"
    rm -rf "$o"/skills/{b_calibrated,c_delta_action,f_calibrated_narrow} "$o"/deployments "$o"/results.json \
      "$o"/report.md "$o"/tracking_heldout.png
    touch "$o/.probe_reuse"
  fi
done
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> "$R/STAGES"; }
floor() {  # GPU NAME SEED
  local t=$(date +%s)
  CUDA_VISIBLE_DEVICES=$1 $(command_of $2 $3) >> "$R/$2.out" 2>&1
  stage floor $2 rc=$? after $(( $(date +%s) - t )) s
}
stage floors start
( while sleep 30; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi \
    --query-gpu=utilization.gpu,memory.used --format=csv,noheader | tr '\n' ' ')"; done ) >> "$R/load.log" 2>&1 &
LOAD=$!
i=0
for n in $RUNS; do
  floor "${gpu[$(( i % ${#gpu[@]} ))]}" $n ${n##*_s} &
  i=$(( i + 1 )); sleep "${STAGGER:-10}"
done
wait $(jobs -p | grep -v "^$LOAD$")
kill $LOAD 2>/dev/null
stage floors done
