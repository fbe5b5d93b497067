"""Compile one generated replay kernel's module into Warp's kernel cache, in a process of its own.

    python compile_worker.py GENERATED_FILE KERNEL ARCH PTX CACHE_DIR

Run by :func:`.kernels.compile_batch` as a script (so that it imports Warp alone, not the package): NVRTC compiles
of several modules in threads of one process slow each other down (on a 16-core host 14 modules took 28 s in
15 threads against 17 s in 15 processes: ``benchmarks/results/compile/pieces_nvrtc_scaling_h100.txt``). The file is
one :func:`.cache.load_module` wrote; it is executed only if its content still matches the hash in its name, under
the module name and file name ``load_module`` gives it, so that Warp's module hash is the parent's. The GPU is not
touched (NVRTC runs on the CPU): the parent hides it with ``CUDA_VISIBLE_DEVICES``.
"""

import hashlib
import linecache
import os
import sys
import types


def main() -> None:
    path, kernel, arch, ptx, cache = sys.argv[1:6]
    with open(path, "rb") as f:
        data = f.read()
    key = hashlib.sha256(data).hexdigest()[:20]
    if os.path.basename(path) != f"replay_{key}.py":
        sys.exit(f"{path}: its content does not match its name; not compiled")
    src = data.decode()
    import warp as wp

    wp.config.quiet = True
    wp.init()
    wp.config.kernel_cache_dir = cache
    name = f"wresdyn_replay_{key}"
    linecache.cache[path] = (len(src), None, src.splitlines(True), path)
    mod = types.ModuleType(name)
    mod.__file__ = path
    sys.modules[name] = mod
    exec(compile(src, path, "exec"), mod.__dict__)
    wp.compile_aot_module(getattr(mod, kernel).module, arch=int(arch), use_ptx=ptx == "1")


if __name__ == "__main__":
    main()
