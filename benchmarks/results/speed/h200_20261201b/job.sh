#!/bin/bash
# profile one gradient-fit iteration at 1024 windows x 64 steps, fused then plain, on GPU 0; budget $1 seconds
set -u
R=/root/res; mkdir -p $R; T0=$(date +%s)
{ date -u; nvidia-smi; nproc; uptime; python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"; echo "tree: $(git rev-parse HEAD 2>/dev/null || cat .dev/COMMIT)"; } > $R/machine.txt 2>&1
for mode in fused plain; do
  left=$(( $1 - ($(date +%s) - T0) )); [ $left -lt 20 ] && break
  flag=""; [ $mode = fused ] && flag=--fused
  s=$(date +%s.%N)
  timeout $left python3 benchmarks/speed/profile_gradfit.py --device cuda:0 --windows 1024 --horizon 64 --repeat 20 $flag \
    --top 40 --json $R/profile_$mode.json > $R/profile_$mode.txt 2>&1
  rc=$?
  echo "whole command: $(python3 -c "import time;print(round(time.time()-$s,1))") s rc=$rc" >> $R/profile_$mode.txt
done
date -u >> $R/machine.txt
