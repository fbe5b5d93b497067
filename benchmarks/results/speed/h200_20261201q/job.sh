#!/usr/bin/env bash
# One H200: the gradient fit's CUDA default (the tile path, GradFitConfig.network_paths) against the plain path in the
# same run: 2000 iterations at 1024 windows, default, plain, default; the CUDA tests of the default's graph against
# eager and of the fused and tile paths; the default command's first fit on a fresh cache (the shipped kernels) and warm.
set -u
END=$1; R=/root/res; mkdir -p $R
export PYTHONUNBUFFERED=1 OMP_NUM_THREADS=1
stage() { echo "$(date -u +%T) $*" >> $R/STAGES; }
left() { echo $(( END - $(date +%s) )); }
{ date -u; nvidia-smi -L; nproc; python3 -c "import torch,warp;print('torch',torch.__version__,'warp',warp.__version__)"; \
  echo "tree: $(cat .dev/COMMIT)"; } > $R/machine.txt 2>&1
stage start
unset WRESDYN_TILE_BLOCK
export WRESDYN_ADJOINT_PIECES=0  # every fit on the one adjoint kernel, which warmup compiles
{ time timeout 150 python3 -m wresdyn.cli warmup --device cuda:0; } > $R/cli_warmup.log 2>&1; stage "cli warmup rc=$?"
fit=(python3 benchmarks/speed/gradfit_2000.py --device cuda:0 --windows 1024)
timeout 90 "${fit[@]}" --iterations 20 --json $R/warmup.json > $R/warmup.log 2>&1; stage "warmup rc=$?"
run() { local n=$1; shift; timeout 50 "${fit[@]}" --iterations 2000 "$@" --json $R/$n.json > $R/$n.log 2>&1; stage "$n rc=$?"; }
run default1
timeout 130 python3 -m pytest -q -rA -p no:cacheprovider tests/learn/test_gradfit_2000.py tests/fit/test_fused_network.py \
  "tests/learn/test_learner_speed_paths.py::test_graph_replayed_fit_iteration_equals_the_eager_one" \
  > $R/tests.txt 2>&1; stage "tests rc=$?"
run plain --plain
run default2
[ $(left) -gt 100 ] && { SHIPPED=1 HELPER_PAIRS=0 TOTAL=$(( $(left) - 5 )) bash benchmarks/speed/coldfit.sh \
  $R/coldfit_default > $R/coldfit_default.out 2>&1; stage "coldfit default rc=$?"; }
rm -rf $R/coldfit_default/runs $R/coldfit_default/wc_prebuilt
python3 .dev/summary.py $R > $R/summary.txt 2>&1 || true
echo done > $R/DONE
