# The cartpole's cold first fit on the CPU to its first iteration, from an empty Warp cache, without and with the
# modules `wresdyn warmup --export` wrote (the tree of 95e67c0; cwd the repository, OMP_NUM_THREADS=1, PYTHONPATH=.).
# 1. data: tests/conftest.py's record_multisine of newton:cartpole.urdf (examples/gains/cartpole.toml), Mismatch(),
#    train 2 / validation 1 / heldout 1 / ood 1 trajectories of 0.4 s, saved as /tmp/pbprof/cart.npz
# 2. the export, on a cache of its own:
WARP_CACHE_PATH=/tmp/pbprof/wexp WRESDYN_KERNEL_DIR=/tmp/pbprof/kexp python -m wresdyn.cli warmup --no-shipped \
    --robot newton:cartpole.urdf --gains examples/gains/cartpole.toml --export /tmp/pbprof/P
# 3. two rounds, each cold (no prebuilt folder) then with the export; the script makes an empty Warp cache and
#    kernel folder for every run
for r in 1 2; do
  WRESDYN_PREBUILT_KERNELS=/tmp/pbprof/none python benchmarks/speed/first_fit_profile.py /tmp/pbprof/cart.npz \
      --device cpu > cold_$r.txt 2>&1
  WRESDYN_PREBUILT_KERNELS=/tmp/pbprof/P python benchmarks/speed/first_fit_profile.py /tmp/pbprof/cart.npz \
      --device cpu > prebuilt_$r.txt 2>&1
done
