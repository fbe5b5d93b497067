#!/bin/bash
# Device job (2 x H200 host): the floor benchmark's six full-size runs resumed, three a GPU (default on GPU 0, uneven on
# GPU 1), each training what is left of (d), (e), (f) and then deploying; the humanoid fight's two mujoco.sysid peers
# resumed on the host's cores at nice 19.
# Usage (repository root, the runs' folders in .dev/data and .dev/data2): bash job.sh PEER_SECONDS
set -u
PEER_S=${1:-1400}
R=/root/res; mkdir -p $R
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
D=.dev/data
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep "Model name"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat $D/COMMIT)"; } > $R/machine.txt 2>&1
stage start
export WARP_CACHE_PATH=/root/wc_floor
for r in floor_def_s0 floor_def_s1 floor_def_s2; do cp -r $D/$r /root/$r; done
for r in floor_unv_s0 floor_unv_s1 floor_unv_s2 unv_fits; do cp -r .dev/data2/$r /root/$r; done
P="a_nominal b_calibrated c_delta_action d_oracle e_randomized f_calibrated_narrow"
floor() {  # GPU NAME SEED MISMATCH DATA [FLAGS]
  local g=$1 n=$2 s=$3 m=$4 d=$5; shift 5
  local t=$(date +%s)
  CUDA_VISIBLE_DEVICES=$g python3 -m wresdyn.cli deploy $d --floor --full --device cuda:0 --mismatch $m --seed $s \
    --nominal floor_nominal --policies $P --no-animation --quiet --out /root/$n "$@" >> $R/$n.out 2>&1
  stage floor $n rc=$? after $(( $(date +%s) - t )) s
}
DEF="data/mismatch_default.toml data/dataset.npz"
UNV="data/mismatch_uneven.toml data/uneven/dataset.npz"
CD="--calibrated /root/floor_def_s0/calibrated --delta /root/floor_def_s0/delta_action"
CU="--calibrated /root/unv_fits/calibrated --delta /root/unv_fits/delta_action"
floor 0 floor_def_s0 0 $DEF &
floor 1 floor_unv_s0 0 $UNV $CU &
sleep 10; floor 0 floor_def_s1 1 $DEF $CD &
floor 1 floor_unv_s1 1 $UNV $CU &
sleep 10; floor 0 floor_def_s2 2 $DEF $CD &
floor 1 floor_unv_s2 2 $UNV $CU &
stage floors launched
sleep 60
mkdir -p /root/peer_out/default /root/peer_out/uneven
cp -r $D/peers/default/peer /root/peer_out/default/; cp -r $D/peers/uneven/peer /root/peer_out/uneven/
for m in default uneven; do
  ( UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh $m \
      peer --threads 14 --max-seconds $PEER_S --resume > $R/peer_$m.log 2>&1; stage peer $m ended rc=$? ) &
done
stage peers launched
( while sleep 30; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi --query-gpu=utilization.gpu,memory.used --format=csv,noheader | tr '\n' ' ')"; done ) > $R/load.log 2>&1 &
wait
