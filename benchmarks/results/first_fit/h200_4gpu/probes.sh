#!/bin/bash
# The fresh-cache probes after launch.sh's four fits, on the same machine (GPUs 2 and 3 once free); fit() as runfit below.
ts() { python3 -u -c '
import sys,time
t0=time.time()
for l in sys.stdin: sys.stdout.write(f"{time.time()-t0:8.2f} {l}")'; }
# fresh Warp cache, the CUDA driver's cache as the earlier fits left it
( export CUDA_VISIBLE_DEVICES=2 WARP_CACHE_PATH=/root/wc_A; python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 --identify.fused --out /root/runs/fit_fused_A 2>&1 | ts > fit_fused_fresh_cache_again.log ) &
# fresh Warp cache, the driver's cache off
( export CUDA_VISIBLE_DEVICES=3 WARP_CACHE_PATH=/root/wc_B CUDA_CACHE_DISABLE=1; python3 -m wresdyn.cli fit data/dataset.npz --device cuda:0 --identify.fused --out /root/runs/fit_fused_B 2>&1 | ts > fit_fused_fresh_cache_no_driver_cache.log ) &
wait
runfit() { # GPU NAME OPTLEVEL: Warp writes CUBIN (NVRTC runs ptxas) instead of PTX for the driver to JIT
  export CUDA_VISIBLE_DEVICES=$1 WARP_CACHE_PATH=/root/wc_$2 CUDA_CACHE_DISABLE=1
  python3 -c "
import sys, runpy, warp as wp
wp.config.cuda_output = 'cubin'
if '$3' != '-': wp.config.optimization_level = int('$3')
sys.argv = ['wresdyn', 'fit', 'data/dataset.npz', '--device', 'cuda:0', '--identify.fused', '--eval', '--out', '/root/runs/fit_$2']
runpy.run_module('wresdyn.cli', run_name='__main__')" 2>&1 | ts > fit_$2.log
}
( runfit 2 fused_cubin_O3 - ) &
( runfit 3 fused_cubin_O1 1 ) &
wait
