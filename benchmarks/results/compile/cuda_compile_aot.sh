#!/bin/bash
# usage: cuda_compile_aot.sh TREE TAG KERNEL OPT : cuda_compile_aot.py with empty caches, importing the wresdyn of TREE
TREE=$1; TAG=$2; shift 2
D=/tmp/adj/aotc_$TAG; rm -rf $D; mkdir -p $D
cd $TREE
echo "# $(date -u +%FT%TZ) $TREE ($(cd $TREE && PYTHONPATH=$TREE /work/main/.venv/bin/python -c "import wresdyn; print(wresdyn.__file__)" 2>/dev/null)) $TAG load $(cut -d' ' -f1-3 /proc/loadavg)"
PYTHONPATH=$TREE WARP_CACHE_PATH=$D/warp WRESDYN_KERNEL_DIR=$D/src OMP_NUM_THREADS=1 /work/main/.venv/bin/python -u /work/wt-adjoint/benchmarks/results/compile/cuda_compile_aot.py $TAG "$@" 2>&1 | grep -v "CUDA warning"
echo "# $(date -u +%FT%TZ) load $(cut -d' ' -f1-3 /proc/loadavg)"
rm -rf $D
