#!/usr/bin/env bash
# pairs.sh N AFTER_TREE PREFIX FLAGS...: N pairs of the small fit, before then after, back to back
n=$1; after=$2; pre=$3; shift 3
for i in $(seq 1 $n); do
  /tmp/fw57/one.sh /tmp/fw57/before ${pre}_before$i "$@"
  /tmp/fw57/one.sh $after ${pre}_after$i "$@"
done
