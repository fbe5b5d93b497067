#!/bin/bash
# device: after install.py; PYTHONPATH exported by the caller. Where an online update's GPU time goes (CUPTI),
# the replay kernels from the prefilled cache (laned, one-kernel adjoint; benchmarks/speed/prefill_cuda_cache.py --pieces 0).
R=/root/res; mkdir -p $R /root/wc
for c in /root/stage_c/*/; do cp -r $c/* /root/wc/; done
export PYTHONUNBUFFERED=1 WARP_CACHE_PATH=/root/wc
{ nvidia-smi; nproc; lscpu | grep "Model name"; python3 -c "import torch,warp;print(torch.__version__, warp.__version__)"; ls /root/wc/1.19.0 | wc -l; } > $R/machine.txt 2>&1
for W in 8 256; do
  python3 benchmarks/speed/adapt_profile.py --device cuda --kernels 5 --set windows=$W > $R/adapt_kernels_w$W.txt 2>&1
  echo w$W > $R/STAGE
done
python3 benchmarks/speed/adapt_profile.py --device cuda > $R/adapt_w8.txt 2>&1
echo done > $R/DONE
