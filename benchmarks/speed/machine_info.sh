#!/usr/bin/env bash
# The machine a speed figure ran on, written as each speed script's OUT/machine.txt: the date, the GPUs, the cores,
# the load, torch's and Warp's versions, the commit and any changed tracked file.
#
#   bash benchmarks/speed/machine_info.sh [PYTHON] > OUT/machine.txt
py=${1:-python3}
date -u; nvidia-smi 2>&1 | head -20; nproc; uptime
"$py" -c "import torch, warp; print('torch', torch.__version__, 'warp', warp.__version__)" 2>&1
git log -1 --format='%H %s' 2>&1; git status --porcelain --untracked-files=no 2>&1 | head -20
