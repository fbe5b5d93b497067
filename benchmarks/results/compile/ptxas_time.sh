#!/bin/bash
# usage: ptxas_time.sh TAG PTX [ptxas options]: ptxas 13.0 (the H200 host's driver generation) on NVRTC 13.4's PTX
# (its trailing NUL dropped, .version 9.4 -> 9.0, the newest ptxas 13.0 reads), CPU-seconds of the child
TAG=$1; PTX=$2; shift 2
OUT=$(dirname "$0")/cuda_probe_cpu.txt
tr -d '\000' < $PTX | sed 's/^\.version 9\.4/.version 9.0/' > /tmp/$TAG.in.ptx
echo "# $(date -u +%FT%TZ) $TAG: ptxas -arch=sm_90 $* $(basename $PTX) (load $(cut -d' ' -f1-3 /proc/loadavg))" | tee -a $OUT
/usr/bin/time -f "$TAG: ptxas %e s wall, %U+%S CPU-s, max RSS %M kB, exit %x" timeout ${LIMIT:-1800} /usr/local/cuda-13.0/bin/ptxas -arch=sm_90 "$@" -o /tmp/$TAG.cubin /tmp/$TAG.in.ptx 2>&1 | grep -v "^ptxas info    : Compiling\|Function properties" | tail -8 | tee -a $OUT
echo "# done $(date -u +%FT%TZ), load $(cut -d' ' -f1-3 /proc/loadavg); cubin $(stat -c %s /tmp/$TAG.cubin 2>/dev/null) bytes" | tee -a $OUT
