#!/bin/bash
# no-drift screen of the policy's validation timeline (explore.py) with the committed code
cd /work/wt33
OLD="confirm_leave=1 detect_jump_confirm=false effort_overall=0"
for sd in 0 1 2; do
  for s in "$OLD" "confirm_leave=1 detect_jump_confirm=false" "confirm_leave=1 effort_overall=0" "detect_jump_confirm=false effort_overall=0" \
           "confirm_leave=1" "detect_jump_confirm=false" "effort_overall=0" \
           "confirm_leave=2" "confirm_leave=3" "confirm_leave=4" "confirm_leave=5" "detect=false confirm_leave=1" "detect=false"; do
    PYTHONPATH=/work/wt33 OMP_NUM_THREADS=1 .venv/bin/python benchmarks/results/adapt_drift/leave/screen/explore.py --set seed=$sd $s 2>&1 | grep -E "^(ratios|RESULT)"
  done
done
