#!/usr/bin/env bash
# PPO on 1 and 2 GPUs through torchrun, in one go: the residual PPO and the floor benchmark's skill PPO, each at N and
# 2N worlds on one GPU and N per GPU on two; the residual with rsl-rl's update and with the one-sync update
# (ppo.one_sync_update); the scaling efficiency of each; the residual's time to a validation target on 1 and 2 GPUs.
# Optional steps: rsl-rl's options' throughput on one GPU, the update's profile. Run from the repository root
# (benchmarks/speed/ppo_scaling.py, benchmarks/speed/ppo_update_profile.py say what each measures):
#
#   bash benchmarks/speed/gpu_scaling.sh OUT
#
# Environment: N (residual worlds per GPU, 4096), SN (skill worlds per GPU, 4096: the floor benchmark's full size),
# ITERS (timed residual iterations per case, 15), SKILL_ITERS (5), SKILL_ONE_SYNC (1: the skill with the one-sync
# update too; 0 by default), TTF (target: PD-only validation error / TTF, 2.0; 0 skips it), TTF_MAX (iterations at
# most, 300), TTF_CHECK (validation every, 25), TTF_ONE_SYNC (1: the one-sync update, the default; 0: rsl-rl's),
# TTF_MORE (more time-to-target runs on one GPU, each a case's options or rsl_rl: "rsl_rl one_sync+mb2"; none by
# default), MAIN (0 skips steps 1 and 2: a second call for the optional steps, TTF=0 MAIN=0 OPTIONS=1 PROFILE=1),
# OPTIONS (1: rsl-rl's options' throughput on one GPU, COMPILE=1 with torch.compile; 0 by default), PROFILE
# (1: the update's profile on two GPUs, 2: and on one; 0 by default), PYTHON (python3), DEVICE (cuda; cpu runs every
# step at tiny sizes over gloo, the check before a GPU run: DEVICE=cpu N=16 SN=8 ITERS=2 SKILL_ITERS=1 TTF_MAX=4
# TTF_CHECK=2 SKILL_ONE_SYNC=1 TTF_MORE=rsl_rl OPTIONS=1 COMPILE=1 PROFILE=2 EXTRA="--warmup 1 --skill-motions 1"
# bash benchmarks/speed/gpu_scaling.sh OUT), EXTRA (more arguments of ppo_scaling.py), GPUS (the GPUs to use, 0,1; one
# GPU, e.g. GPUS=3, skips the steps on two).
# Every step writes OUT/<step>.txt (and .json); the tables are OUT/table.txt. Kernels compile in the first step
# (its cases' "built in" times) and are cached for the rest.
set -uo pipefail
out=${1:?usage: gpu_scaling.sh OUT}
mkdir -p "$out"
export PYTHONPATH=$PWD${PYTHONPATH:+:$PYTHONPATH} PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
py=${PYTHON:-python3}
dev=${DEVICE:-cuda}
n=${N:-4096}
sn=${SN:-4096}
extra=${EXTRA:-}
its="--iterations ${ITERS:-15} --skill-iterations ${SKILL_ITERS:-5}"
gpus=${GPUS:-0,1}
two=$([[ $gpus == *,* ]] && echo 1 || echo 0)
# shellcheck disable=SC2086
run() {  # run NPROC SCRIPT ARGS...: the script under torchrun on the first NPROC GPUs of GPUS
  local np=$1 script=$2; shift 2
  CUDA_VISIBLE_DEVICES=$(cut -d, -f1-"$np" <<< "$gpus") $py -m torch.distributed.run --standalone \
    --nproc_per_node "$np" "benchmarks/$script" --device "$dev" "$@"
}
step() {  # step NAME COMMAND...: its output in OUT/NAME.txt, its wall-clock on the terminal
  local name=$1 t0=$SECONDS; shift
  "$@" > "$out/$name.txt" 2>&1
  echo "$name: rc=$? in $((SECONDS - t0)) s"
  grep -E "^(residual|skill|ttf)" "$out/$name.txt"
}
{ nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader || echo "no nvidia-smi"
  $py -c "import torch, warp, rsl_rl; print('torch', torch.__version__, 'warp', warp.__version__)"
  git log -1 --format='commit %h %s' && git diff --quiet HEAD -- wresdyn benchmarks || echo "(with uncommitted changes)"
} > "$out/machine.txt" 2>&1
cat "$out/machine.txt"
skill1=("skill:$sn" "skill:$((2 * sn))")
skill2=("skill:$((2 * sn))")
if [[ ${SKILL_ONE_SYNC:-0} != 0 ]]; then skill1+=("skill:$sn+one_sync"); skill2+=("skill:$((2 * sn))+one_sync"); fi
if [[ ${MAIN:-1} != 0 ]]; then
  # 1. one GPU: N and 2N worlds
  step one_gpu run 1 ppo_scaling.py $its $extra --json "$out/one_gpu.json" --cases \
    "residual:$n" "residual:$((2 * n))" "residual:$n+one_sync" "${skill1[@]}"
  # 2. two GPUs: N per GPU
  if [[ $two == 1 ]]; then
    step two_gpus run 2 ppo_scaling.py $its $extra --json "$out/two_gpus.json" --cases \
      "residual:$((2 * n))" "residual:$((2 * n))+one_sync" "${skill2[@]}"
  fi
  $py benchmarks/speed/ppo_scaling.py --table "$out/one_gpu.json" $(ls "$out/two_gpus.json" 2>/dev/null) \
    | tee -a "$out/table.txt"
fi
# 3. time to the same validation target, 1 GPU (N worlds) and 2 GPUs (N per GPU)
ttf=${TTF:-2.0}
if [[ $ttf != 0 ]]; then
  targs=(--ttf "$ttf" --max-iterations "${TTF_MAX:-300}" --check "${TTF_CHECK:-25}" --out "$out/ttf")
  [[ ${TTF_ONE_SYNC:-1} != 0 ]] && targs+=(--one-sync)
  step ttf_one_gpu run 1 ppo_scaling.py "${targs[@]}" --envs "$n" --json "$out/ttf_one_gpu.json"
  [[ $two == 1 ]] && step ttf_two_gpus run 2 ppo_scaling.py "${targs[@]}" --envs "$((2 * n))" \
    --json "$out/ttf_two_gpus.json"
  for opts in ${TTF_MORE:-}; do  # more updates on one GPU, e.g. TTF_MORE="rsl_rl one_sync+mb2"
    step "ttf_one_gpu_${opts//+/-}" run 1 ppo_scaling.py --ttf "$ttf" --max-iterations "${TTF_MAX:-300}" \
      --check "${TTF_CHECK:-25}" --out "$out/ttf" --envs "$n" --ttf-options "${opts/rsl_rl/}" \
      --json "$out/ttf_one_gpu_${opts//+/-}.json"
  done
  $py benchmarks/speed/ppo_scaling.py --table "$out"/ttf_*.json | tee -a "$out/table.txt"
fi
# 4. what rsl-rl offers, one GPU at N worlds: mixed precision, fewer mini-batches, torch.compile (their effect on
#    learning is measured on validation, docs/results/learners-speed.md)
if [[ ${OPTIONS:-0} != 0 ]]; then
  cases=("residual:$n" "residual:$n+bf16" "residual:$n+mb2" "residual:$n+one_sync+mb2")
  [[ ${COMPILE:-0} != 0 ]] && cases+=("residual:$n+compile" "residual:$n+one_sync+compile")
  step options run 1 ppo_scaling.py $its $extra --json "$out/options.json" --cases "${cases[@]}"
  $py benchmarks/speed/ppo_scaling.py --table $(ls "$out/one_gpu.json" 2>/dev/null) "$out/options.json" \
    | tee -a "$out/table.txt"
fi
# 5. where the update's time goes: rsl-rl's update and the one-sync update, two GPUs (PROFILE=2: and one)
if [[ ${PROFILE:-0} != 0 ]]; then
  for opt in false true; do
    [[ $two == 1 ]] && step "profile_two_gpus_one_sync_$opt" run 2 ppo_update_profile.py --envs "$((2 * n))" \
      --iterations 5 --set "ppo.one_sync_update=$opt"
    if [[ ${PROFILE} == 2 ]]; then
      step "profile_one_gpu_one_sync_$opt" run 1 ppo_update_profile.py --envs "$n" --iterations 5 \
        --set "ppo.one_sync_update=$opt"
    fi
  done
  tail -n 22 "$out"/profile_*.txt
fi
echo "total: $SECONDS s"
