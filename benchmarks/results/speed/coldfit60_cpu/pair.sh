#!/usr/bin/env bash
# before (HEAD 46df1d2 exported to /tmp/coldfit60_before) then after (the worktree), back to back, NAME suffix $1
for side in before after; do
  tree=/tmp/coldfit60_before; [ $side = after ] && tree=/work/wt/coldfit60
  /tmp/coldfit60_runs/one.sh $tree ${side}$1
done
