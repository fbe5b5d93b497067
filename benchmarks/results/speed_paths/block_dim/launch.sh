#!/bin/bash
# device: after install.py; PYTHONPATH exported by the caller. Replay kernels' CUDA block size: 4 variants, caches
# prefilled on the project machine (benchmarks/speed/prefill_cuda_cache.py --pieces 0), merged into /root/wc.
R=/root/res; mkdir -p $R /root/runs /root/wc
for c in /root/stage_c/*/; do cp -r $c/* /root/wc/; done
export PYTHONUNBUFFERED=1 WARP_CACHE_PATH=/root/wc WRESDYN_ADJOINT_PIECES=0
{ nvidia-smi; nproc; python3 -c "import torch,warp;print(torch.__version__, warp.__version__)"; ls /root/wc/1.19.0 | wc -l; } > $R/machine.txt 2>&1
V="b256:256:0 b32:32:0 b64:64:0 b32s:32:1"
each() { for v in $V; do IFS=: read n b s <<< "$v"; WRESDYN_REPLAY_BLOCK_DIM=$b WRESDYN_REPLAY_SMEM_SPILL=$s "$@" "$n"; done; }
prof() { python3 benchmarks/speed/profile_gradfit.py --device cuda:0 --windows 1024 --horizon 64 --repeat 20 --json $R/profile_$1.json > $R/profile_$1.txt 2>&1; }
bench() { python3 -m wresdyn.cli bench --device cuda:0 --solvers replay --worlds 1024,16384 --json $R/bench_$1.json > $R/bench_$1.txt 2>&1; }
adapt() { for w in 8 256; do python3 benchmarks/speed/adapt_profile.py --device cuda --set windows=$w > $R/adapt_$1_w$w.txt 2>&1; done; }
ttf() { python3 benchmarks/speed/time_to_fidelity.py --device cuda:0 --learners gradient --windows 1024 --check 50 --out /root/runs/ttf_$1 > $R/ttf_$1.txt 2>&1; cp /root/runs/ttf_$1/results.json $R/ttf_$1.json 2>/dev/null; }
each prof; echo prof > $R/STAGE
each bench; echo bench > $R/STAGE
each ttf; echo ttf > $R/STAGE
each adapt
echo done > $R/DONE
