#!/usr/bin/env bash
# The learners' speed paths on one GPU, in one go (what made benchmarks/results/speed_paths/):
#   1. the CUDA-graph test (graph-replayed ReplayEnv step equals the eager one);
#   2. PPO s per iteration, rsl-rl's collect / learn split and env-steps/s, environment step from a CUDA graph
#      and eager side by side (256, 4096, 16384 envs), and the gradient fit's throughput (1024 windows, graph and
#      eager), then the profile of one gradient-fit iteration;
#   3, 4. time to fidelity on validation: the gradient fit (1024 windows, graph and eager) to PD-only / 3, PPO
#      (4096 envs) to / 2.5.
#
#   bash benchmarks/speed/gpu_speed_paths.sh OUT_DIR [STEPS]      # STEPS: which of 1 2 3 4 to run (default all)
#
# Environment: PYTHON (default python), DEVICE (cuda:0), PPO_ITERS (the cap of step 4, 2000), RUNS (run folders).
set -uo pipefail
out=${1:?usage: gpu_speed_paths.sh OUT_DIR [STEPS]}
steps=${2:-1 2 3 4}
py=${PYTHON:-python}
dev=${DEVICE:-cuda:0}
runs=${RUNS:-/tmp/wresdyn_speed_runs}  # run folders (checkpoints), outside OUT_DIR
mkdir -p "$out" "$runs"
export PYTHONUNBUFFERED=1
for s in $steps; do
  case $s in
    1) $py -m pytest -q -p no:cacheprovider tests/learn/test_learner_speed_paths.py -k graph 2>&1 | tee "$out/graph_test.txt" ;;
    2) $py benchmarks/speed/learners.py --device "$dev" --envs 256,4096,16384 --graphs on,off --ppo-iterations 20 \
         --windows 1024 --grad-iterations 20 --json "$out/learners.json" 2>&1 | tee "$out/learners.txt"
       $py benchmarks/speed/profile_gradfit.py --device "$dev" --windows 1024 --horizon 64 --json "$out/profile_gradfit.json" \
         2>&1 | tee "$out/profile_gradfit.txt" ;;
    3) $py benchmarks/speed/time_to_fidelity.py --device "$dev" --learners gradient --windows 1024 --check 50 --no-graph \
         --out "$runs/ttf_gradient" 2>&1 | tee "$out/time_to_fidelity_gradient.txt"
       cp "$runs/ttf_gradient/results.json" "$out/time_to_fidelity_gradient.json" ;;
    4) $py benchmarks/speed/time_to_fidelity.py --device "$dev" --learners ppo --envs 4096 --ratio 2.5 \
         --ppo-iterations "${PPO_ITERS:-2000}" --check 25 --out "$runs/ttf_ppo" 2>&1 | tee "$out/time_to_fidelity_ppo.txt"
       cp "$runs/ttf_ppo/results.json" "$out/time_to_fidelity_ppo.json"
       cp "$runs/ttf_ppo/ppo/train_summary.json" "$out/ttf_ppo_train_summary.json" ;;
  esac
done
