#!/bin/bash
# Device job (2 x H200 host, fourth session): the floor benchmark's six full-size runs resumed through
# benchmarks/skills/floor_fair_resume.sh (three a GPU: (f) finished, then every policy deployed); on the host's cores
# meanwhile wresdyn's `refine` recipe on both humanoid mismatches (Warp CPU backend, fresh kernel caches) and the two
# mujoco.sysid peers at nice 19; each GPU, once its floors end, fits `refine` on that GPU (fresh kernel cache).
# Usage (repository root; run folders in .dev/data*, gathered into /root/src): bash job.sh PEER_SECONDS
set -u
PEER_S=${1:-1000}
R=/root/res; mkdir -p $R /root/src
export PYTHONPATH=/tmp/site:/tmp/site/cmeel.prefix/lib/python3.12/site-packages:$PWD PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
{ date -u; nvidia-smi; echo "cores: $(nproc --all)"; lscpu | grep "Model name"; uptime
  python3 -c "import torch,warp,mujoco,newton;print('torch',torch.__version__,'warp',warp.__version__,'mujoco',mujoco.__version__,'newton',newton.__version__)"
  echo "tree: $(cat .dev/data/COMMIT)"; } > $R/machine.txt 2>&1
stage start
for d in .dev/data .dev/data2 .dev/data3; do cp -r $d/floor_* $d/unv_fits /root/src/ 2>/dev/null; done
ls /root/src >> $R/machine.txt
export WARP_CACHE_PATH=/root/wc_floor
refine_gpu() {  # GPU MISMATCH, after that GPU's floors
  local t=$(date +%s)
  CUDA_VISIBLE_DEVICES=$1 WARP_CACHE_PATH=/root/wc_rgpu_$2 UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 \
    bash benchmarks/peers/humanoid.sh $2 wresdyn --device cuda:0 --recipe refine --tag refine_cuda > $R/refine_cuda_$2.log 2>&1
  stage refine cuda $2 rc=$? after $(( $(date +%s) - t )) s
}
# floor_fair_resume.sh runs all six; per GPU end is read from STAGES, so the GPU refine legs wait for all six
( bash benchmarks/skills/floor_fair_resume.sh /root/src $R; stage floors all ended
  refine_gpu 0 default & refine_gpu 1 uneven & wait ) &
stage floors launched
sleep 20
mkdir -p /root/peer_out/default /root/peer_out/uneven
for m in default uneven; do
  ( t=$(date +%s); WARP_CACHE_PATH=/root/wc_rcpu_$m UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 \
      bash benchmarks/peers/humanoid.sh $m wresdyn --device cpu --recipe refine --tag refine_peer_host > $R/refine_cpu_$m.log 2>&1
    stage refine cpu $m rc=$? after $(( $(date +%s) - t )) s ) &
done
stage refine cpu launched
sleep 20
cp -r .dev/data/peer_default /root/peer_out/default/peer; cp -r .dev/data/peer_uneven /root/peer_out/uneven/peer
for m in default uneven; do
  ( UNEVEN=data/uneven/dataset.npz OUT=/root/peer_out PYTHON=python3 nice -n 19 bash benchmarks/peers/humanoid.sh $m \
      peer --threads 16 --max-seconds $PEER_S --resume > $R/peer_$m.log 2>&1; stage peer $m ended rc=$? ) &
done
stage peers launched
wait
stage all done
