#!/bin/bash
# Device job (2 x H200 host): the floor benchmark's six full-size runs (default and uneven mismatch, seeds 0-2,
# policies a-f, three per GPU), the humanoid fight's two mujoco.sysid peers on the host's cores (nice 19), and the
# speed checks of the session's new GPU paths on GPU 0 beside them. Results in /root/res, runs in /root/floor_*.
# Usage (repository root): bash job.sh PEER_SECONDS
set -u
PEER_S=${1:-1200}
R=/root/res; mkdir -p $R /root/runs
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
D=.dev/data
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep "Model name"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  python3 -c "import mujoco_warp; print('mujoco_warp', getattr(mujoco_warp, '__version__', '?'))"
  echo "tree: $(cat $D/COMMIT)"; ls ~/.cache/warp 2>&1; } > $R/machine.txt 2>&1
stage start

# --- host cores: the humanoid fight's peers, resumed from their checkpoints (nice 19, 12 threads each)
mkdir -p /root/peer_out/default /root/peer_out/uneven
cp -r $D/peers/default/peer /root/peer_out/default/; cp -r $D/peers/uneven/peer /root/peer_out/uneven/
for m in default uneven; do
  ( UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh $m \
      peer --threads 12 --max-seconds $PEER_S --resume > $R/peer_$m.log 2>&1; stage peer $m ended rc=$? ) &
done

# --- the floor: three runs per GPU; seeds 1 and 2 reuse seed 0's stand corrections (one calibration per mismatch)
export WARP_CACHE_PATH=/root/wc_floor
cp -r $D/floor_def_s0 /root/floor_def_s0; cp -r $D/unv_fits /root/unv_fits
P="a_nominal b_calibrated c_delta_action d_oracle e_randomized f_calibrated_narrow"
floor() {  # GPU NAME SEED MISMATCH DATA [FLAGS]
  local g=$1 n=$2 s=$3 m=$4 d=$5; shift 5
  local t=$(date +%s)
  CUDA_VISIBLE_DEVICES=$g python3 -m wresdyn.cli deploy $d --floor --full --device cuda:0 --mismatch $m --seed $s \
    --nominal floor_nominal --policies $P --no-animation --quiet --out /root/$n "$@" > $R/$n.out 2>&1
  stage floor $n rc=$? after $(( $(date +%s) - t )) s
}
DEF="data/mismatch_default.toml data/dataset.npz"
UNV="data/mismatch_uneven.toml data/uneven/dataset.npz"
CD="--calibrated /root/floor_def_s0/calibrated --delta /root/floor_def_s0/delta_action"
CU="--calibrated /root/unv_fits/calibrated --delta /root/unv_fits/delta_action"
floor 1 floor_unv_s0 0 $UNV $CU &
sleep 40
floor 0 floor_def_s0 0 $DEF &
floor 1 floor_unv_s1 1 $UNV $CU &
sleep 40
floor 0 floor_def_s1 1 $DEF $CD &
floor 1 floor_unv_s2 2 $UNV $CU &
sleep 20
floor 0 floor_def_s2 2 $DEF $CD &
stage floors launched

# --- GPU 0: checks of the session's new GPU paths, beside three floor runs (so: a loaded GPU)
[ -f $D/speed.sh ] && CUDA_VISIBLE_DEVICES=0 bash $D/speed.sh $R > $R/speed.log 2>&1
stage speed checks done
wait
