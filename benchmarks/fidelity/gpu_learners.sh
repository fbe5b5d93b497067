#!/usr/bin/env bash
# The learner runs of issues 4 and 5 on a GPU host, in one go (what made benchmarks/results/learners_gpu*):
#   1. throughput on the GPU: PPO env-steps/s and s per iteration (256-4096 envs; SolverReplay vs Newton's
#      MuJoCo-Warp solver) and the gradient fit (32-1024 windows);
#   2. full-size runs on the GPU, evaluated: PPO with 4096 envs (residual authority 0.25 and 0.5) and the
#      gradient fit with 1024 windows;
#   3. on the host's CPU cores, one cell per core: the ablation grid and, beside it, the delay sweep.
#
#   bash benchmarks/fidelity/gpu_learners.sh OUT_DIR [MAIN_JOBS] [DELAY_JOBS]
#
# Environment: GPU_B (device of the second GPU stream: the gradient fit and the second PPO run; default
# cuda:0, cuda:1 on a 2-GPU host), PPO_ITERS (1000), FIT_ITERS (2000), ABL_PPO_ITERS (500), WRESDYN (the CLI,
# default `wresdyn`), PYTHON, WRESDYN_DATA. Every step writes under OUT_DIR and resumes when run again.
set -uo pipefail
out=${1:?usage: gpu_learners.sh OUT_DIR [MAIN_JOBS] [DELAY_JOBS]}
main_jobs=${2:-12}
delay_jobs=${3:-12}
data=${WRESDYN_DATA:-data/dataset.npz}
gpu_b=${GPU_B:-cuda:0}
mkdir -p "$out"
export PYTHONUNBUFFERED=1
w=${WRESDYN:-wresdyn}
py=${PYTHON:-python}

(
  $py benchmarks/speed/learners.py --device cuda:0 --envs 256,1024,4096 --solvers auto,mujoco --ppo-iterations 5 \
      --windows 32,256,1024 --grad-iterations 5 --json "$out/learners_gpu.json" > "$out/learners_gpu.txt" 2>&1
  $w train "$data" --device cuda:0 --num-envs 4096 --iterations "${PPO_ITERS:-1000}" --save-interval 250 \
      --out "$out/ppo_gpu" --eval > "$out/ppo_gpu.txt" 2>&1
) &
stream_a=$!
(
  $w fit "$data" --device "$gpu_b" --windows 1024 --iterations "${FIT_ITERS:-2000}" --out "$out/fit_gpu" --eval \
      > "$out/fit_gpu.txt" 2>&1
  $w train "$data" --device "$gpu_b" --num-envs 4096 --iterations "${PPO_ITERS:-1000}" --save-interval 250 \
      --fraction 0.5 --out "$out/ppo_gpu_f05" --eval > "$out/ppo_gpu_f05.txt" 2>&1
) &
stream_b=$!
$w ablate --data "$data" --out "$out/ablation" --delays-only --delays 0,0.005,0.01 --jobs "$delay_jobs" \
    --gradient-iterations 2000 --segments 4 > "$out/delay_sweep.txt" 2>&1 &
delays=$!
$w ablate --data "$data" --out "$out/ablation" --jobs "$main_jobs" --ppo-iterations "${ABL_PPO_ITERS:-500}" \
    --gradient-iterations 2000 --segments 4 > "$out/ablation.txt" 2>&1
wait $stream_a $stream_b $delays
tail -n 3 "$out"/*.txt
