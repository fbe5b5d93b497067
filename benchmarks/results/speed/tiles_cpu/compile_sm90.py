"""The tile kernels' CUDA compile for sm_90 (H100/H200) on a machine without a GPU: NVRTC (and, with MathDx, its GEMMs'
link-time step) through Warp's compile_aot_module, in a fresh Warp cache; seconds per kernel and the shared memory per
block that Warp records for each.

    PYTHONPATH=. python benchmarks/results/speed/tiles_cpu/compile_sm90.py 84,256,128,64,21 16 32 0   # Warp's GEMM
    PYTHONPATH=. python benchmarks/results/speed/tiles_cpu/compile_sm90.py 84,256,128,64,21 16 32 1   # MathDx
"""

import glob
import sys
import tempfile
import time

import warp as wp

wp.config.quiet = True
scratch = tempfile.mkdtemp()
wp.config.kernel_cache_dir = scratch + "/cache"
wp.init()
from wresdyn.learn import tile_mlp  # noqa: E402

dims = tuple(int(a) for a in sys.argv[1].split(","))
rows, chunk, mathdx = int(sys.argv[2]), int(sys.argv[3]), bool(int(sys.argv[4]))
print(f"widths {dims}, rows {rows}, chunk {chunk}, mathdx {mathdx}")
for kernel in tile_mlp._kernels(dims, 1.0, rows, chunk, mathdx):
    t = time.time()
    wp.compile_aot_module(kernel.module, arch=90, module_dir=scratch + "/aot", use_ptx=False)
    print(f"{kernel.key}: compiled for sm_90 in {time.time() - t:.1f} s")
for meta in sorted(glob.glob(scratch + "/aot/*.meta")):
    print(open(meta).read())
