#!/usr/bin/env bash
# pairs.sh N FLAGS...: N pairs of the small fit, before then after, back to back
n=$1; shift
for i in $(seq 1 $n); do
  /tmp/fs57/one.sh /tmp/fs57/before small_beforeF$i "$@"
  /tmp/fs57/one.sh /tmp/fs57/after7 small_final$i "$@"
done
