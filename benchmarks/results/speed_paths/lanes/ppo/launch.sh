#!/bin/bash
# device: after install.py; PYTHONPATH exported. Residual PPO throughput at 4096 envs, one thread per world and branch
# against one per world (the replay env's forward step), empty Warp cache (forward kernels only).
R=/root/res; mkdir -p $R; export PYTHONUNBUFFERED=1 WARP_CACHE_PATH=/root/wc
{ nvidia-smi; nproc; python3 -c "import torch,warp;print(torch.__version__, warp.__version__)"; } > $R/machine.txt 2>&1
for v in lanes:1 one:0 lanes2:1; do IFS=: read n l <<< "$v"
  WRESDYN_REPLAY_LANES=$l python3 benchmarks/speed/learners.py --device cuda:0 --envs 4096 --windows "" --ppo-iterations 15 --json $R/ppo_$n.json > $R/ppo_$n.txt 2>&1
  echo $n > $R/STAGE
done
echo done > $R/DONE
