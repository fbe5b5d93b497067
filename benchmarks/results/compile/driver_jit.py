"""Time the CUDA driver's JIT (ptxas inside libcuda) on PTX files, without Warp: ``cuModuleLoadData`` on device 0.

usage: CUDA_CACHE_DISABLE=1 python3 driver_jit.py FILE.ptx...   (the cache off, so every load compiles)

Prints the driver's CUDA version (``cuDriverGetVersion``) and, per file, the CUresult (0: loaded; 222: the PTX's
ISA is newer than this driver reads) and the seconds the load took.
"""
import ctypes
import sys
import time

cu = ctypes.CDLL("libcuda.so.1")
v = ctypes.c_int()
cu.cuDriverGetVersion(ctypes.byref(v))
print("cuDriverGetVersion", v.value, flush=True)
cu.cuInit(0)
dev = ctypes.c_int()
cu.cuDeviceGet(ctypes.byref(dev), 0)
ctx = ctypes.c_void_p()
cu.cuDevicePrimaryCtxRetain(ctypes.byref(ctx), dev)
cu.cuCtxSetCurrent(ctx)
for f in sys.argv[1:]:
    data = open(f, "rb").read() + b"\0"
    mod = ctypes.c_void_p()
    t, c = time.perf_counter(), time.process_time()
    r = cu.cuModuleLoadData(ctypes.byref(mod), data)
    print(f"driver JIT of {f}: CUresult {r}, {time.perf_counter() - t:.1f} s wall, {time.process_time() - c:.1f} CPU-s",
          flush=True)
