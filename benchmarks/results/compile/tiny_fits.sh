#!/bin/bash
# usage: tiny_fits.sh TREE TAG : the tiny hybrid fit and the tiny network fit in TREE, outputs under /tmp/adj/runs/TAG
TREE=$1; TAG=$2; OUT=/tmp/adj/runs/$TAG; rm -rf $OUT; mkdir -p $OUT; cd $TREE
export OMP_NUM_THREADS=1
echo "# $(date -u +%FT%TZ) $TREE load $(cut -d' ' -f1-3 /proc/loadavg)"
/work/main/.venv/bin/python -m wresdyn.cli fit data/dataset.npz --out $OUT/fit --iterations 20 --windows 8 --identify.iterations 20 --identify.windows 8 > $OUT/fit.log 2>&1; echo "hybrid exit $?"
/work/main/.venv/bin/python -m wresdyn.cli fit data/dataset.npz --model network --out $OUT/net --iterations 20 --windows 8 > $OUT/net.log 2>&1; echo "network exit $?"
echo "# $(date -u +%FT%TZ) load $(cut -d' ' -f1-3 /proc/loadavg)"
