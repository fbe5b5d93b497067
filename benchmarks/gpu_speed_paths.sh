#!/usr/bin/env bash
# The learners' speed paths on one GPU, in one go (what made benchmarks/results/speed_paths/):
#   1. the CUDA-graph test (graph-replayed ReplayEnv step equals the eager one);
#   2. PPO s per iteration, rsl-rl's collect / learn split and env-steps/s, environment step from a CUDA graph
#      and eager side by side (256, 4096, 16384 envs), and the gradient fit's throughput (1024 windows);
#   3. time to fidelity: gradient fit (1024 windows) and PPO (4096 envs) to PD-only / 3 on validation.
#
#   bash benchmarks/gpu_speed_paths.sh OUT_DIR [STEPS]      # STEPS: which of 1 2 3 to run (default "1 2 3")
#
# Environment: PYTHON (default python), DEVICE (cuda:0), PPO_ITERS (the cap of step 3, 2000).
set -uo pipefail
out=${1:?usage: gpu_speed_paths.sh OUT_DIR [STEPS]}
steps=${2:-1 2 3}
py=${PYTHON:-python}
dev=${DEVICE:-cuda:0}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
for s in $steps; do
  case $s in
    1) $py -m pytest -q -p no:cacheprovider tests/test_learner_speed_paths.py -k graph 2>&1 | tee "$out/graph_test.txt" ;;
    2) $py benchmarks/learners.py --device "$dev" --envs 256,4096,16384 --graphs on,off --ppo-iterations 20 \
         --windows 1024 --grad-iterations 20 --json "$out/learners.json" 2>&1 | tee "$out/learners.txt" ;;
    3) $py benchmarks/time_to_fidelity.py --device "$dev" --windows 1024 --envs 4096 \
         --ppo-iterations "${PPO_ITERS:-2000}" --check 25 --out "$out/ttf" 2>&1 | tee "$out/time_to_fidelity.txt" ;;
  esac
done
