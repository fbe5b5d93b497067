#!/usr/bin/env bash
# PPO on the hybrid (identified physics + residual), both mismatches, one GPU, runs sharing it. Staged like every
# GPU run here (../shared/device/README.md), run from the repository root on the device; STAGE holds the uneven
# dataset (`wresdyn collect --mismatch data/mismatch_uneven.toml --out X` -> uneven.npz) and the physics of
# `wresdyn identify` on each (phys_default.json, phys_uneven.json).
#   STAGE=.dev/w10 OUT=DIR ITERS=300 bash benchmarks/fidelity/gpu_ppo_hybrid.sh full
#       the five runs of benchmarks/results/grey_box/soft_friction/ppo_hybrid/ (the soft friction law)
#   STAGE=.dev/w0 OUT=DIR ITERS=1500 / ITERS=600 ... full / sweep
#       benchmarks/results/grey_box/ppo_hybrid/ (the previous friction law; full_*.txt, sweep_*.txt)
set -u
OUT=${OUT:?}
ITERS=${ITERS:-300}
STAGE=${STAGE:-.dev/w10}
mkdir -p /tmp/src && cp "$STAGE"/*.npz "$STAGE"/*.json /tmp/src/
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name --format=csv,noheader | tee $OUT/gpu.txt
run() { name=$1; shift; python -m wresdyn train "$@" --device cuda:0 --iterations $ITERS --save-interval 100 \
        --out $OUT/$name --eval 2>&1 | grep -v "^ \{15,\}\|Learning iteration\|####\|-----\|^$" > $OUT/$name.txt
        echo "$name rc=${PIPESTATUS[0]}" >> $OUT/done.txt; }
if [[ ${1:-full} == sweep ]]; then
  T="--set rewards.sigma_q=0.005 --set rewards.sigma_qd=1.0"
  P="data/dataset.npz --physics /tmp/src/phys_default.json"
  run f005 $P --fraction 0.05 &
  run f005_tight $P --fraction 0.05 $T &
  run f005_tight_std03 $P --fraction 0.05 $T --set residual.init_std=0.3 &
  run f002_tight $P --fraction 0.02 $T &
  run f01_tight $P --fraction 0.1 $T &
  run f05_tight $P --fraction 0.5 $T &
  wait; exit 0
fi
run ppo_hybrid_default data/dataset.npz --physics /tmp/src/phys_default.json &
run ppo_hybrid_default_gru data/dataset.npz --physics /tmp/src/phys_default.json --arch gru &
run ppo_hybrid_default_delta data/dataset.npz --physics /tmp/src/phys_default.json --residual delta_action &
run ppo_hybrid_uneven /tmp/src/uneven.npz --physics /tmp/src/phys_uneven.json &
run ppo_residual_uneven /tmp/src/uneven.npz &
wait
tail -n 4 $OUT/*.txt
