#!/bin/bash
# usage: coldfit.sh TREE TAG [FIT FLAGS...] : a first `wresdyn fit` (hybrid) in TREE with empty Warp and generated-kernel
# caches, each output line stamped with the seconds since the command started. Without flags: the tiny fit of
# MANIFEST.md (20 + 20 iterations x 8 windows). Output folder: /tmp/compile/runs/TAG.
HERE=$(cd "$(dirname "$0")" && pwd)
TREE=$1; TAG=$2; shift 2
FLAGS=${*:-"--iterations 20 --windows 8 --identify.iterations 20 --identify.windows 8"}
OUT=/tmp/compile/runs/$TAG; rm -rf $OUT; mkdir -p $OUT
export WARP_CACHE_PATH=$OUT/warp_cache WRESDYN_KERNEL_DIR=$OUT/kernel_src OMP_NUM_THREADS=1
cd $TREE
echo "# $(date -u +%FT%TZ) tree $TREE ($(git -C $TREE rev-parse --short HEAD 2>/dev/null || echo main-5ad0f1c)) load: $(cut -d' ' -f1-3 /proc/loadavg)"
echo "# WARP_CACHE_PATH=$WARP_CACHE_PATH WRESDYN_KERNEL_DIR=$WRESDYN_KERNEL_DIR OMP_NUM_THREADS=1"
CMD="/work/main/.venv/bin/python -u -m wresdyn.cli fit data/dataset.npz --out $OUT/fit $FLAGS"
echo "# $CMD"
$CMD 2>&1 | /work/main/.venv/bin/python -u "$HERE/stamp.py"
echo "# exit ${PIPESTATUS[0]}  load: $(cut -d' ' -f1-3 /proc/loadavg)"
