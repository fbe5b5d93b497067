#!/bin/bash
# usage: cuda_probe_cpu.sh TAG [compile_cuda_probe.py options] : one NVRTC probe of this tree on this machine's CPU,
# one thread, under a wall-clock limit of ${LIMIT:-1800} s; appends a header line and the probe's line to cuda_probe_cpu.txt.
cd "$(dirname "$0")/../../.."
OUT=benchmarks/results/compile/cuda_probe_cpu.txt
TAG=$1; shift
echo "# $(date -u +%FT%TZ) $(git rev-parse --short HEAD) $TAG: $* (load $(cut -d' ' -f1-3 /proc/loadavg))" | tee -a $OUT
PYTHONPATH=$PWD OMP_NUM_THREADS=1 timeout ${LIMIT:-1800} .venv/bin/python -u benchmarks/compile_cuda_probe.py $TAG "$@" 2>&1 \
  | grep -v -e "CUDA warning" -e "^Warp " -e "^   " | tee -a $OUT
echo "# exit ${PIPESTATUS[0]} at $(date -u +%FT%TZ) (124: stopped at the limit), load $(cut -d' ' -f1-3 /proc/loadavg)" | tee -a $OUT
