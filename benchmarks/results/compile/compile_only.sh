#!/bin/bash
# usage: compile_only.sh TREE TAG ROBOT VARIANTS... : compile_kernels with empty Warp and generated-kernel caches
TREE=$1; TAG=$2; ROBOT=$3; shift 3
OUT=/tmp/compile/runs/$TAG; rm -rf $OUT; mkdir -p $OUT
export WARP_CACHE_PATH=$OUT/warp_cache WRESDYN_KERNEL_DIR=$OUT/kernel_src OMP_NUM_THREADS=1
cd $TREE
echo "# $(date -u +%FT%TZ) tree $TREE load: $(cut -d' ' -f1-3 /proc/loadavg); robot $ROBOT; variants $*"
/work/main/.venv/bin/python -u - "$ROBOT" "$@" <<'PY'
import sys, torch
torch.set_num_threads(1)
from wresdyn.robot.description import load_robot
from wresdyn.sim.warmup import compile_kernels
robot = load_robot(sys.argv[1])
compile_kernels(robot, 500.0, tuple(sys.argv[2:]))
PY
echo "# load after: $(cut -d' ' -f1-3 /proc/loadavg)"
