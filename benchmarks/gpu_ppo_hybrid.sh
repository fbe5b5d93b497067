#!/usr/bin/env bash
# PPO on the hybrid (identified physics + residual), both mismatches, one GPU, runs sharing it
# (benchmarks/results/grey_box/ppo_hybrid/). Staged like every GPU run here (../shared/device/README.md): the
# source at a commit (`git archive -o .dev/w0/src.tar HEAD`), the uneven dataset (`wresdyn collect --mismatch
# data/mismatch_uneven.toml --out X` -> .dev/w0/uneven.npz) and the physics of `wresdyn identify` on each
# (.dev/w0/phys_default.json, phys_uneven.json) in .dev/w0.
#   OUT=DIR ITERS=1500 bash benchmarks/gpu_ppo_hybrid.sh full     # the five runs of full_*.txt
#   OUT=DIR ITERS=600 bash benchmarks/gpu_ppo_hybrid.sh sweep     # the validation sweep of sweep_*.txt
set -u
OUT=${OUT:?}
ITERS=${ITERS:-1500}
rm -rf /tmp/src && mkdir -p /tmp/src && tar -xf .dev/w0/src.tar -C /tmp/src
cp .dev/w0/*.npz .dev/w0/*.json /tmp/src/
cd /tmp/src
export PYTHONPATH=/tmp/site:/tmp/src PYTHONUNBUFFERED=1
nvidia-smi --query-gpu=name --format=csv,noheader | tee $OUT/gpu.txt
run() { name=$1; shift; python -m wresdyn train "$@" --device cuda:0 --iterations $ITERS --save-interval 250 \
        --out $OUT/$name --eval > $OUT/$name.txt 2>&1; echo "$name rc=$?" >> $OUT/done.txt; }
if [[ ${1:-full} == sweep ]]; then
  T="--set rewards.sigma_q=0.005 --set rewards.sigma_qd=1.0"
  P="data/dataset.npz --physics phys_default.json"
  run f005 $P --fraction 0.05 &
  run f005_tight $P --fraction 0.05 $T &
  run f005_tight_std03 $P --fraction 0.05 $T --set residual.init_std=0.3 &
  run f002_tight $P --fraction 0.02 $T &
  run f01_tight $P --fraction 0.1 $T &
  run f05_tight $P --fraction 0.5 $T &
  wait; exit 0
fi
run ppo_hybrid_default data/dataset.npz --physics phys_default.json &
run ppo_hybrid_default_gru data/dataset.npz --physics phys_default.json --arch gru &
run ppo_hybrid_default_delta data/dataset.npz --physics phys_default.json --residual delta_action &
run ppo_hybrid_uneven uneven.npz --physics phys_uneven.json &
run ppo_residual_uneven uneven.npz &
wait
tail -n 4 $OUT/*.txt
