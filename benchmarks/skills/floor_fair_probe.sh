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
# SRC holds the corrections (unvp_fits/calibrated/ and delta_action/, fitted; CAL and DELT below) and, to resume a
# stopped session, the runs' folders as packed (floor_fair_pack.py); they are copied to $ROOT/<name> (ROOT, default
# /root: the absolute paths the skills' config.json files record, so a resume must use the same).
# data/uneven_probe/dataset.npz must exist. GPUS
# (default: every GPU nvidia-smi lists) are the CUDA devices the runs take in turn, started STAGGER s apart (10).
# RUNS (default: all three) narrows the runs to some of them, e.g. RUNS=floor_unvp_s1; a run's seed is the number its
# name ends in, whatever the order. DRY=1 checks the inputs and prints the commands without copying or running anything.
# LOG gets STAGES, <run>.out and load.log as floor_fair_resume.sh writes them. Python is python3; the environment is the
# caller's. Returns when all three have ended; rerun the same command to resume (finished policies and deployments are
# reused).
#
# REUSE=1 keeps the policies KEEP names (default "d_oracle e_randomized": those that use no correction) of earlier
# runs and retrains the others of (b)-(f): seed N runs in $ROOT/floor_unv_sN, the folder the kept policies were trained
# in (the path their config.json files record), set up once from SRC/<BASE>_sN (BASE default floor_unv: the committed
# no-probe runs; BASE=floor_unvp takes them from the probe runs) with the other policies and the earlier results
# removed (a marker file, .probe_reuse, says it was; the base's held-out ledger is kept, so it lists every
# configuration scored on these held-out motions, and gets this one's line). A kept policy must be in the base and its
# config.json must record the corrections path the command passes (CAL for (b) and (f), DELT for (c), none for (d)
# and (e)): otherwise the deploy would refuse it after drawing the motions, so the set-up refuses it at once.
# CAL and DELT (default $ROOT/unvp_fits/calibrated and $ROOT/unvp_fits/delta_action) are the corrections the command
# passes; each lies in SRC at its path under ROOT (CAL=$ROOT/unvp55_fits/calibrated: SRC/unvp55_fits/calibrated).
# NAME (default floor_unvp, never BASE) names the runs: RUNS are NAME_s0..2 and SRC/NAME_sN, where present, is such a
# folder packed by an earlier session and is resumed instead. Pack the folders as usual (floor_fair_pack.py packs
# $ROOT/floor_unv_sN as floor_unv_sN) and keep them as NAME_sN. DRY=1 also prints the set-up, in lines starting "# ".
# EXTRA (default none) is appended to every deploy command, e.g. EXTRA="--randomization.unseen wide" for (f).
set -u
[ $# -eq 2 ] || { echo "usage: floor_fair_probe.sh SRC LOG" >&2; exit 2; }
SRC=$1; R=$2
ROOT=${ROOT:-/root}
DATA=data/uneven_probe/dataset.npz
NAME=${NAME:-floor_unvp}; BASE=${BASE:-floor_unv}
RUNS=${RUNS:-${NAME}_s0 ${NAME}_s1 ${NAME}_s2}
CAL=${CAL:-$ROOT/unvp_fits/calibrated}; DELT=${DELT:-$ROOT/unvp_fits/delta_action}
KEEP=${KEEP:-d_oracle e_randomized}
fail() { echo "error: $*" >&2; exit 2; }
[ -d "$SRC" ] || fail "$SRC is not a folder"
[ -f $DATA ] || fail "$DATA is missing: record it first (wresdyn collect --mismatch data/mismatch_uneven.toml \
--probe-saturation 6 --out data/uneven_probe)"
for c in "$CAL" "$DELT"; do
  [ "${c#$ROOT/}" != "$c" ] || fail "$c is not under ROOT ($ROOT): the skills record the corrections' paths there"
  [ -f "$SRC/${c#$ROOT/}/policy.pt" ] || fail "$SRC/${c#$ROOT/}/policy.pt is missing: fit the corrections first"
done
if [ -z "${GPUS:-}" ]; then
  GPUS=$(nvidia-smi --query-gpu=index --format=csv,noheader 2>/dev/null | tr '\n' ' ')
  [ -n "$GPUS" ] || fail "no GPU found (nvidia-smi lists none); set GPUS to run anyway"
fi
read -r -a gpu <<< "$GPUS"
P="a_nominal b_calibrated c_delta_action d_oracle e_randomized f_calibrated_narrow"
CU="--calibrated $CAL --delta $DELT"
out_of() {  # NAME: the folder a run writes
  if [ "${REUSE:-0}" = 1 ]; then echo "$ROOT/floor_unv_s${1##*_s}"; else echo "$ROOT/$1"; fi
}
command_of() {  # NAME SEED
  echo "python3 -m wresdyn.cli deploy $DATA --floor --full --device cuda:0 --mismatch data/mismatch_uneven.toml" \
    "--seed $2 --nominal floor_nominal --policies $P --no-animation --quiet --out $(out_of $1) $CU${EXTRA:+ $EXTRA}"
}
corr_of() {  # POLICY: the corrections path its config.json must record
  case $1 in b_calibrated|f_calibrated_narrow) echo "$CAL";; c_delta_action) echo "$DELT";; *) echo "";; esac
}
RETRAIN=""
if [ "${REUSE:-0}" = 1 ]; then
  [ "$NAME" != "$BASE" ] || fail "NAME and BASE are both $NAME: the runs must not take the base's name"
  for k in $KEEP; do
    case " ${P#a_nominal } " in *" $k "*) ;; *) fail "KEEP names $k, not one of ${P#a_nominal }";; esac
  done
  for p in ${P#a_nominal }; do case " $KEEP " in *" $p "*) ;; *) RETRAIN="$RETRAIN $p";; esac; done
  for n in $RUNS; do
    from="$SRC/$n"; [ -d "$from" ] || from="$SRC/${BASE}_s${n##*_s}"
    [ -d "$from" ] || fail "REUSE=1 needs $SRC/${BASE}_s${n##*_s} (the base run) or $SRC/$n"
    for k in $KEEP; do
      f="$from/skills/$k/config.json"
      [ -f "$f" ] || fail "KEEP names $k but $f is missing"
      got=$(sed -n 's/^ *"correction": *"\([^"]*\)".*/\1/p' "$f")
      [ "$got" = "$(corr_of $k)" ] || fail "$f records corrections '$got', the command passes '$(corr_of $k)'"
    done
  done
fi
if [ "${DRY:-0}" = 1 ]; then
  if [ "${REUSE:-0}" = 1 ]; then
    for c in "$CAL" "$DELT"; do echo "# $c: from $SRC/${c#$ROOT/} unless there"; done
  fi
  for n in $RUNS; do
    [ "${REUSE:-0}" = 1 ] || continue
    if [ -d "$SRC/$n" ]; then echo "# $n: $(out_of $n) resumed from $SRC/$n"
    else echo "# $n: $(out_of $n) from $SRC/${BASE}_s${n##*_s}, keeping $KEEP, retraining${RETRAIN}"; fi
  done
  i=0
  for n in $RUNS; do
    echo "CUDA_VISIBLE_DEVICES=${gpu[$(( i % ${#gpu[@]} ))]} $(command_of $n ${n##*_s})"; i=$(( i + 1 ))
  done
  exit 0
fi
mkdir -p "$R"
mkdir -p "$ROOT"
for c in "$CAL" "$DELT"; do
  [ -e "$c" ] || { mkdir -p "$(dirname "$c")"; cp -r "$SRC/${c#$ROOT/}" "$c"; }
done
for r in $RUNS; do  # a run folder absent from SRC starts fresh in $ROOT
  o=$(out_of $r)
  [ -d "$SRC/$r" ] && [ ! -e "$o" ] && cp -r "$SRC/$r" "$o"
  if [ "${REUSE:-0}" = 1 ] && [ ! -e "$o/.probe_reuse" ]; then
    [ -e "$o" ] || cp -r "$SRC/${BASE}_s${r##*_s}" "$o"
    for p in $RETRAIN; do rm -rf "$o/skills/$p"; done
    rm -rf "$o"/deployments "$o"/results.json "$o"/report.md "$o"/tracking_heldout.png
    echo "$r: kept $KEEP of $BASE" > "$o/.probe_reuse"
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
