#!/bin/bash
# Device job (2 x H200 host), in order:
#   both GPUs idle: the residual PPO's 2-GPU scaling, three rounds (benchmarks/speed/ppo90.sh), if PPO=1;
#   GPU 0: the floor benchmark's three default-mismatch runs resumed, Isaac Sim 6.2's identification beside them, and
#          the CUDA-graph race checks on that loaded GPU;
#   GPU 1, idle: the first fit cold / exported kernels / warm (benchmarks/speed/coldfit.sh), the gradient fit's 2000
#          iterations; then the three uneven-mismatch floor runs resumed;
#   host cores (nice 19): the humanoid fight's two mujoco.sysid peers resumed, after the PPO rounds.
# Usage (repository root): bash job.sh PEER_SECONDS [PPO]
set -u
PEER_S=${1:-1200}; PPO=${2:-0}
R=/root/res; mkdir -p $R /root/runs
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
D=.dev/data
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep "Model name"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat $D/COMMIT)"; ls ~/.cache/warp 2>&1; } > $R/machine.txt 2>&1
stage start
if [ "$PPO" = 1 ]; then
  WARP_CACHE_PATH=/root/wc_ppo timeout ${PPO_S:-330} bash benchmarks/speed/ppo90.sh $R/ppo90 > $R/ppo90.log 2>&1
  stage ppo90 rc=$?
fi

mkdir -p /root/peer_out/default /root/peer_out/uneven
cp -r $D/peers/default/peer /root/peer_out/default/; cp -r $D/peers/uneven/peer /root/peer_out/uneven/
for m in default uneven; do
  ( UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh $m \
      peer --threads 16 --max-seconds $PEER_S --resume > $R/peer_$m.log 2>&1; stage peer $m ended rc=$? ) &
done

export WARP_CACHE_PATH=/root/wc_floor
for r in floor_def_s0 floor_def_s1 floor_def_s2 floor_unv_s0 floor_unv_s1 floor_unv_s2 unv_fits; do cp -r $D/$r /root/$r; done
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
sleep 20; floor 0 floor_def_s1 1 $DEF $CD &
sleep 20; floor 0 floor_def_s2 2 $DEF $CD &
stage floors on GPU 0 launched
[ -d /root/isaacw ] && ( CUDA_VISIBLE_DEVICES=0 bash $D/isaac.sh /root/isaacw $R ${ISAAC_N:-1} > $R/isaac.log 2>&1 ) &
( sleep 60; CUDA_VISIBLE_DEVICES=0 bash $D/speed.sh $R checks > $R/speed_checks.log 2>&1 ) &

( unset WARP_CACHE_PATH
  GPU=1 TOTAL=${COLDFIT_S:-480} bash benchmarks/speed/coldfit.sh $R/coldfit > $R/coldfit.log 2>&1; stage coldfit rc=$?
  CUDA_VISIBLE_DEVICES=1 CUDA_CACHE_DISABLE=1 bash $D/speed.sh $R gradfit > $R/speed_gradfit.log 2>&1 )
stage speed on GPU 1 done
floor 1 floor_unv_s0 0 $UNV $CU &
sleep 20; floor 1 floor_unv_s1 1 $UNV $CU &
sleep 20; floor 1 floor_unv_s2 2 $UNV $CU &
stage floors on GPU 1 launched
wait
