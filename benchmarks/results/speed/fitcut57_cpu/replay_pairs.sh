#!/usr/bin/env bash
# replay_pairs.sh N: the replay timing of before and after, alternating processes, N rounds
for i in $(seq 1 $1); do
  for side in before after5; do
    echo "$side $(cut -d' ' -f1-3 /proc/loadavg) $(cd /tmp/fs57/$side && PYTHONPATH=/tmp/fs57/$side OMP_NUM_THREADS=1 nice -n 5 /work/main/.venv/bin/python /work/wt/fitspeed57/benchmarks/results/speed/fitcut57_cpu/replay_ab.py data/dataset.npz 5 2>/dev/null)"
  done
done
