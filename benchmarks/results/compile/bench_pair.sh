#!/bin/bash
# usage: bench_pair.sh OUTFILE TREE_A TAG_A TREE_B TAG_B [ROUNDS] : wresdyn bench --solvers replay at 16 and 128 worlds, interleaved
OUT=$1; A=$2; TA=$3; B=$4; TB=$5; R=${6:-2}
export OMP_NUM_THREADS=1
for r in $(seq $R); do for pair in "$A $TA" "$B $TB"; do set -- $pair
  echo "## round $r: $2 ($1) $(date -u +%FT%TZ) load $(cut -d' ' -f1-3 /proc/loadavg)"
  (cd $1 && /work/main/.venv/bin/python -m wresdyn.cli bench --solvers replay --worlds 16,128 2>&1 | grep "replay ")
done; done > $OUT
echo "# end $(date -u +%FT%TZ) load $(cut -d' ' -f1-3 /proc/loadavg)" >> $OUT
