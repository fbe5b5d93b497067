#!/bin/bash
# Where each run stands: its latest checkpoint per policy, the deploy log's last line, the stages and the load.
for r in /root/floor_*; do
  echo "== $(basename $r): $(for p in $r/skills/*/; do n=$(ls $p 2>/dev/null | grep -o 'model_[0-9]*' | sort -t_ -k2 -n | tail -1); echo -n "$(basename $p)=${n#model_} "; done)"
  tail -c 300 $r/deploy.log 2>/dev/null | tail -1 | cut -c1-250
done
cat /root/res/STAGES; tail -2 /root/res/load.log; for f in /root/res/refine_*.log /root/res/peer_*.log; do echo "-- $f: $(tail -1 $f | cut -c1-200)"; done
