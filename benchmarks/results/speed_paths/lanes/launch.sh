#!/bin/bash
# device: after install.py; PYTHONPATH exported by the caller. SolverReplay's branch lanes (one thread per branch of
# the base) against one thread per world, blocks of 32 both; caches prefilled on the project machine
# (benchmarks/speed/prefill_cuda_cache.py --pieces 0, WRESDYN_REPLAY_LANES=0 / 1), merged into /root/wc.
R=/root/res; mkdir -p $R /root/runs /root/wc
for c in /root/stage_c/*/; do cp -r $c/* /root/wc/; done
export PYTHONUNBUFFERED=1 WARP_CACHE_PATH=/root/wc WRESDYN_ADJOINT_PIECES=0
{ nvidia-smi; nproc; python3 -c "import torch,warp;print(torch.__version__, warp.__version__)"; ls /root/wc/1.19.0 | wc -l; } > $R/machine.txt 2>&1
V="lanes:1 one:0"
each() { for v in $V; do IFS=: read n l <<< "$v"; WRESDYN_REPLAY_LANES=$l "$@" "$n"; done; }
prof() { python3 benchmarks/speed/profile_gradfit.py --device cuda:0 --windows 1024 --horizon 64 --repeat 20 --json $R/profile_$1.json > $R/profile_$1.txt 2>&1; }
ttf() { python3 benchmarks/speed/time_to_fidelity.py --device cuda:0 --learners gradient --windows 1024 --check 50 --out /root/runs/ttf_$1 > $R/ttf_$1.txt 2>&1; cp /root/runs/ttf_$1/results.json $R/ttf_$1.json 2>/dev/null; }
fit() { s=$(date +%s.%N); python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 --eval --out /root/runs/fit_$1 > $R/fit_$1.log 2>&1; echo "whole command: $(python3 -c "import time;print(round(time.time()-$s,1))") s" >> $R/fit_$1.log; }
bench() { python3 -m wresdyn.cli bench --device cuda:0 --solvers replay --worlds 1024,16384 --json $R/bench_$1.json > $R/bench_$1.txt 2>&1; }
adapt() { python3 benchmarks/speed/adapt_profile.py --device cuda --set windows=8 > $R/adapt_$1_w8.txt 2>&1; }
each prof; echo prof > $R/STAGE
each ttf; echo ttf > $R/STAGE
each fit; echo fit > $R/STAGE
each bench; echo bench > $R/STAGE
python3 benchmarks/results/speed_paths/lanes/gradcheck.py $R/g_cuda.pt cuda:0 > $R/gradcheck_cuda.txt 2>&1
python3 benchmarks/results/speed_paths/lanes/gradcheck.py $R/g_cpu.pt cpu > $R/gradcheck_cpu.txt 2>&1
python3 -c "
import torch; a=torch.load('$R/g_cuda.pt'); b=torch.load('$R/g_cpu.pt')
print('max abs diff', (a-b).abs().max().item(), 'scale', b.abs().max().item(), 'relative', ((a-b).abs().max()/b.abs().max()).item())" > $R/gradcheck.txt 2>&1
python3 -m pytest -q -rA tests/learn/test_learner_speed_paths.py -k graph -p no:cacheprovider > $R/graph_tests.txt 2>&1
echo tape > $R/STAGE
each adapt
echo done > $R/DONE
