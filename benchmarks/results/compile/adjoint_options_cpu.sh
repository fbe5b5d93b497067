#!/bin/bash
# usage: adjoint_options_cpu.sh TAG OPT INLINE MIN_LEN [REF] : one configuration of adjoint_options.py on the CPU, empty caches.
# As run for MANIFEST.md (no PYTHONPATH), the script imported the wresdyn of the venv's editable install, main 0d94b00:
# the option comparison is on main's generated code (the adjoint always runs the friction solve).
TAG=$1; shift
D=/tmp/adj/cache_$TAG; rm -rf $D; mkdir -p $D
cd /work/wt-adjoint
echo "# $(date -u +%FT%TZ) $TAG load $(cut -d' ' -f1-3 /proc/loadavg)"
WARP_CACHE_PATH=$D/warp WRESDYN_KERNEL_DIR=$D/src OMP_NUM_THREADS=1 /work/main/.venv/bin/python -u benchmarks/results/compile/adjoint_options.py cpu 64 $TAG "$@" 2>&1 | grep -v "CUDA warning"
echo "# $(date -u +%FT%TZ) load $(cut -d' ' -f1-3 /proc/loadavg)"
rm -rf $D
