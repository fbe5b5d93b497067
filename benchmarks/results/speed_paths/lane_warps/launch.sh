#!/bin/bash
# device: after install.py; PYTHONPATH exported by the caller (the working tree last). Laned replay kernels with each
# branch's threads rounded up to a warp (new) against the branches sharing warps at small batches (base: .dev/base, the
# package at f53932f); caches prefilled on the project machine (.dev/c_lanes: base; .dev/c_lanes2: new).
R=/root/res; mkdir -p $R/base $R/new /root/wc_base /root/wc_new
cp -r /root/stage_c/lanes/* /root/wc_base/; cp -r /root/stage_c/lanes2/* /root/wc_new/
export PYTHONUNBUFFERED=1
{ nvidia-smi; nproc; lscpu | grep "Model name"; python3 -c "import torch,warp;print(torch.__version__, warp.__version__)"; } > $R/machine.txt 2>&1
BASEPATH=/root/repo/.dev/base:$PYTHONPATH
for d in scenes data benchmarks; do ln -sfn /root/repo/$d /root/repo/.dev/base/$d; done  # wresdyn.paths.REPO
v() {  # NAME then the command
  local n=$1; shift
  if [ $n = base ]; then (cd /root/repo/.dev/base && WARP_CACHE_PATH=/root/wc_base PYTHONPATH=$BASEPATH "$@")
  else WARP_CACHE_PATH=/root/wc_new "$@"; fi
}
for n in base new; do
  v $n python3 -c "import wresdyn, wresdyn.paths as p; print(wresdyn.__file__, p.REPO)" > $R/$n/which.txt 2>&1
  v $n python3 /root/repo/benchmarks/speed/adapt_profile.py --device cuda --kernels 5 > $R/$n/adapt_kernels_w8.txt 2>&1
  echo $n-k > $R/STAGE
done
for rep in 1 2; do for n in base new; do
  v $n python3 /root/repo/benchmarks/speed/adapt_profile.py --device cuda > $R/$n/adapt_w8_$rep.txt 2>&1
done; done
echo plain > $R/STAGE
for n in base new; do
  v $n python3 -m wresdyn.cli bench --device cuda:0 --solvers replay --worlds 4,8,24,64,1024 --json $R/$n/bench.json > $R/$n/bench.txt 2>&1
done
echo bench > $R/STAGE
for n in base new; do
  v $n python3 /root/repo/benchmarks/speed/adapt_profile.py --device cuda --set windows=256 > $R/$n/adapt_w256.txt 2>&1
done
echo done > $R/DONE
