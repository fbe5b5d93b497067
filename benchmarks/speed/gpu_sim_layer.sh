#!/usr/bin/env bash
# The GPU runs of issue 11 (one simulation layer), in two phases of under 10 minutes each:
#   check: SolverReplay and Simulator on the device (CUDA graphs vs launches vs CPU), learner throughput
#          (PPO 256-4096 envs, gradient fit 32-1024 windows) to compare with wave 1's learners_gpu figures;
#   sweep: the PPO defaults re-chosen on validation (benchmarks/fidelity/sweeps/ppo_defaults_validation.txt, 1800 it.,
#          256 envs, 4 runs sharing the GPU, ~0.5 s per iteration each). Runs resume when repeated (two calls).
#
#   bash benchmarks/speed/gpu_sim_layer.sh check|sweep OUT_DIR [LIMIT_S]
#
# Environment: PYTHON (default python), WRESDYN_DATA (default data/dataset.npz).
set -uo pipefail
phase=${1:?usage: gpu_sim_layer.sh check|sweep OUT_DIR [LIMIT_S]}
out=${2:?usage: gpu_sim_layer.sh check|sweep OUT_DIR [LIMIT_S]}
limit=${3:-540}
py=${PYTHON:-python}
data=${WRESDYN_DATA:-data/dataset.npz}
export PYTHONUNBUFFERED=1 WRESDYN="$py -m wresdyn"
mkdir -p "$out"
case "$phase" in
  check)
    $py benchmarks/fidelity/check_device.py --device cuda:0 2>&1 | tee "$out/check_device.txt"
    $py benchmarks/speed/learners.py --device cuda:0 --envs 256,1024,4096 --ppo-iterations 5 --windows 32,256,1024 \
        --grad-iterations 5 --json "$out/learners_gpu.json" 2>&1 | tee "$out/learners_gpu.txt"
    ;;
  sweep)
    bash benchmarks/fidelity/ppo_sweep.sh benchmarks/fidelity/sweeps/ppo_defaults_validation.txt "$out/ppo" 1800 "$limit" \
        2>&1 | tee "$out/ppo_sweep.txt"
    ;;
  *) echo "gpu_sim_layer.sh: unknown phase '$phase' (check or sweep)" >&2; exit 2 ;;
esac
