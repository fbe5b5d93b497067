#!/bin/bash
# Where each run stands: its latest checkpoint per policy and the deploy log's last line.
for r in /root/floor_*; do
  echo "== $(basename $r): $(for p in $r/skills/*/; do n=$(ls $p 2>/dev/null | grep -o 'model_[0-9]*' | sort -t_ -k2 -n | tail -1); echo -n "$(basename $p)=${n#model_} "; done)"
  tail -c 300 $r/deploy.log 2>/dev/null | tail -1 | cut -c1-250
  for p in d_oracle e_randomized f_calibrated_narrow; do [ -f $r/skills/$p/train.log ] && echo "  $p: $(tail -1 $r/skills/$p/train.log | cut -c1-160)"; done
done
tail -3 /root/res/STAGES; tail -2 /root/res/load.log
