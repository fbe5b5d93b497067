#!/bin/bash
# device: after install.py; PYTHONPATH exported by the caller. Fast math for the replay kernels, blocks of 32 both:
# caches prefilled on the project machine (benchmarks/speed/prefill_cuda_cache.py --pieces 0), merged into /root/wc.
R=/root/res; mkdir -p $R /root/runs /root/wc
for c in /root/stage_c/*/; do cp -r $c/* /root/wc/; done
export PYTHONUNBUFFERED=1 WARP_CACHE_PATH=/root/wc
{ nvidia-smi; nproc; python3 -c "import torch,warp;print(torch.__version__, warp.__version__)"; } > $R/machine.txt 2>&1
V="b32:0 b32f:1"
each() { for v in $V; do IFS=: read n f <<< "$v"; WRESDYN_REPLAY_FAST_MATH=$f "$@" "$n"; done; }
prof() { python3 benchmarks/speed/profile_gradfit.py --device cuda:0 --windows 1024 --horizon 64 --repeat 20 --json $R/profile_$1.json > $R/profile_$1.txt 2>&1; }
ttf() { python3 benchmarks/speed/time_to_fidelity.py --device cuda:0 --learners gradient --windows 1024 --check 50 --out /root/runs/ttf_$1 > $R/ttf_$1.txt 2>&1; cp /root/runs/ttf_$1/results.json $R/ttf_$1.json 2>/dev/null; }
fit() { python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 --eval --out /root/runs/fit_$1 > $R/fit_$1.log 2>&1; }
each prof; echo prof > $R/STAGE
each fit; echo fit > $R/STAGE
each ttf
echo done > $R/DONE
