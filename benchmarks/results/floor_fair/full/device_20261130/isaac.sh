#!/bin/bash
# Isaac Sim 6.2's System Identification (isaacsim.robot_setup.sysid) on the humanoid's data, on one GPU (the caller
# sets CUDA_VISIBLE_DEVICES): its recipe as prepared by benchmarks/peers/isaac_sim.py, one iteration first (the
# time per iteration on this GPU), then scored. Usage: bash isaac.sh WHEELS R MAX_ITERATIONS
W=$1; R=$2; N=${3:-1}; P=/root/isaac; S=$R/isaac; mkdir -p $P $S
stage() { echo "$(date -u +%T) $* (load $(cut -d' ' -f1-3 /proc/loadavg))" >> $R/STAGES; }
unz() { python3 -c "import sys,zipfile; [zipfile.ZipFile(w).extractall(sys.argv[1]) for w in sys.argv[2:]]" "$@"; }
unz $P/site $W/isaacsim_robot_setup-6.2.0.0-*.whl
unz $P/pins $W/newton-1.6.1-*.whl $W/mujoco-3.12.0-*.whl $W/mujoco_warp-3.12.0-*.whl $W/newton_usd_schemas-0.5.0-*.whl \
    $W/pyyaml-6.0.4-*.whl
tar xzf $W/carb_from_isaacsim_kernel-6.2.0.0.tar.gz -C $P
ls $P $P/pins > $S/install.txt 2>&1; stage isaac installed
python3 benchmarks/peers/isaac_sim.py prepare data/dataset.npz --out $P/run --device cuda:0 > $S/prepare.log 2>&1
stage isaac prepared rc=$?
s=$(date +%s)
PYTHONPATH=$P/pins:$PYTHONPATH timeout ${ISAAC_TIMEOUT:-1500} python3 -X faulthandler benchmarks/peers/isaac_sim.py solve \
  $P/run --isaac $P/site --kit $P/isaacsim/kit --featherstone-substeps 40 --max-iterations $N > $S/solve.log 2>&1
rc=$?; echo "solve: $(( $(date +%s) - s )) s rc=$rc" >> $S/solve.log; stage isaac solve rc=$rc
nvidia-smi --query-gpu=memory.used --format=csv >> $S/solve.log
python3 benchmarks/peers/isaac_sim.py score data/dataset.npz $P/run > $S/score.log 2>&1; stage isaac score rc=$?
cp $P/run/*.json $P/run/*.jsonl $P/run/*.usda $S/ 2>/dev/null
