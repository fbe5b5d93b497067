#!/bin/bash
# waits for the main run's corrections, then restarts it with --finetune 30 (the fit is reused)
MAIN=5778
while ! grep -q "^\[2/4\]" /tmp/cpu55/cpu_run.log; do sleep 10; done
awk '{print "main utime_s", $14/100, "stime_s", $15/100}' /proc/$MAIN/stat > /tmp/cpu55/main_cpu_at_fit.txt
date -u >> /tmp/cpu55/main_cpu_at_fit.txt
kill $MAIN
sleep 3
cd /work/wt/cpu55 && export PYTHONPATH=$PWD OMP_NUM_THREADS=1
date -u > /tmp/cpu55/main2_start.txt
/usr/bin/time -v /work/main/.venv/bin/python -m wresdyn.cli deploy --floor --mismatch data/mismatch_default.toml --finetune 30 --out /tmp/cpu55/cpu_run > /tmp/cpu55/cpu_run2.log 2>&1
