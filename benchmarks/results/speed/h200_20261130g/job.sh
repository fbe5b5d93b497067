#!/bin/bash
# Device job (one H200): 1. the first fit cold / warm / warm eager (coldfit.sh SHIPPED=1 NO_GRAPH=1), the GPU alone;
# 2. physical_limit.py at 4096 and 16384 worlds (mujoco_warp's humanoid with --overflow_behavior=continue), alone;
# 3. the uneven floor's (f) retrained with the unseen parameters' wide ranges from IsaacLab (candidate C of
#    floor_fair/kick55/NEXT.md) on floor_unvp_s{0,1,2}, the three seeds side by side on GPU 0, stopped at END
#    (epoch seconds) and packed for a resume.
# Usage (repository root; inputs in .dev/data, .dev/data2): bash job.sh END_EPOCH
set -u
END=${1:?END epoch}
R=/root/res; S=/root/srcc; mkdir -p $R $S/unvp_fits data/uneven_probe
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
sha256sum data/dataset.npz > /dev/null; cp .dev/data/uneven_probe.npz data/uneven_probe/dataset.npz
cp -r .dev/data/unvp_fits/calibrated .dev/data/unvp_fits/delta_action $S/unvp_fits/
cp -r .dev/data/floor_unvp_s2 .dev/data2/floor_unvp_s0 .dev/data2/floor_unvp_s1 $S/
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep "Model name"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat .dev/data/COMMIT)"; sha256sum data/dataset.npz data/uneven_probe/dataset.npz; ls $S; } > $R/machine.txt 2>&1
( while sleep 30; do echo "$(date -u +%T) $(cut -d' ' -f1-3 /proc/loadavg) $(nvidia-smi \
    --query-gpu=utilization.gpu,memory.used --format=csv,noheader | tr '\n' ' ')"; done ) >> $R/load.log 2>&1 &
stage start
GPU=0 SHIPPED=1 NO_GRAPH=1 TOTAL=300 bash benchmarks/speed/coldfit.sh $R/coldfit > $R/coldfit.log 2>&1
stage "coldfit rc=$?"
mkdir -p $R/plim
timeout 240 python3 benchmarks/speed/physical_limit.py $R/plim --device cuda:0 --worlds 4096,16384 > $R/plim/stdout.txt 2>&1
stage "plim rc=$?"
X="--randomization.unseen wide --randomization.unseen-mass-add-kg -5 5 --randomization.unseen-com-offset 0.05 0.05 0.01"
( REUSE=1 BASE=floor_unvp NAME=floor_unvpc KEEP="b_calibrated c_delta_action d_oracle e_randomized" GPUS="0 0 0" \
    EXTRA="$X" bash benchmarks/skills/floor_fair_probe.sh $S $R/floors > $R/floors.log 2>&1; stage "floors rc=$?" ) &
fl=$!
while kill -0 $fl 2>/dev/null && [ $(date +%s) -lt $END ]; do sleep 5; done
if kill -0 $fl 2>/dev/null; then
  stage "floors stopped at END"; pkill -TERM -f "[w]resdyn.cli deploy"; sleep 20
fi
wait $fl 2>/dev/null
python3 benchmarks/skills/floor_fair_pack.py $R/pack /root > $R/pack.log 2>&1
for d in $R/pack/floor_unv_s*; do [ -d "$d" ] && mv "$d" "${d/floor_unv_s/floor_unvpc_s}"; done
stage packed
stage done
