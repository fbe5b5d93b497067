"""A first run's compile on a GPU, in a fresh process with empty caches: which output Warp picks on this driver, how
long ``compile_kernels`` takes for the default fit's modules (forward and the adjoint), and how NVRTC's time splits
between its front end and ptxas for the adjoint step; optionally a code-generation choice and the fused
identification's iteration time with it.

    CUDA_CACHE_DISABLE=1 python benchmarks/speed/cuda_cold_compile.py [--inline 1|0|none] [--min-len N] [--opt-level N]
        [--split] [--identify] [--cache DIR] [--device cuda:0]

Every run makes its own empty Warp and generated-kernel caches (deleted at the end), so run it once per choice, each
in a new process. ``--inline``/``--min-len``: the outlined chunks' ``@wp.func`` hint and size (the solver's CUDA
default: ``1``, 500 statements; see ``codegen.generate_source``); ``--opt-level``: Warp's ``optimization_level``
module option of the adjoint module (NVRTC's ``-O``; Warp's CUDA default is 3). ``--split``: after the timed
compile, compile the adjoint step again ahead of time for this GPU's architecture to PTX (NVRTC's front end) and to
CUBIN (front end and ptxas), each into an empty folder, so cubin minus PTX is ptxas. ``--identify``: then run
``benchmarks/speed/profile_identify.py --fused`` on the same device (the iteration's milliseconds with these modules).
``--cache DIR``: use this Warp kernel cache instead of an empty one, and keep it (e.g. one that
``benchmarks/speed/prefill_cuda_cache.py`` filled on another machine: then ``compile_kernels`` should only load).
"""

from __future__ import annotations

import argparse
import functools
import os
import runpy
import sys
import time
from pathlib import Path

from compile_cuda_probe import in_scratch, load_average, with_opt_level  # this folder: the script's own

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--device", default="cuda:0")
    p.add_argument("--inline", default=None, choices=("1", "0", "none"), help="default: the solver's choice")
    p.add_argument("--min-len", type=int, default=None, help="chunk size in statements (default: emit.outline's)")
    p.add_argument("--opt-level", type=int, default=None, help="optimization_level of the adjoint module")
    p.add_argument("--split", action="store_true", help="also time NVRTC to PTX and to CUBIN for the adjoint step")
    p.add_argument("--identify", action="store_true", help="then time a fused identification iteration")
    p.add_argument("--cache", default=None, help="a Warp kernel cache to use (and keep) instead of an empty one")
    in_scratch("cold_compile_", run, p.parse_args())


def run(args, scratch: Path) -> None:
    import warp as wp

    wp.config.kernel_cache_dir = args.cache or str(scratch / "warp")
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim.solver_replay import codegen
    from wresdyn.sim.solver_replay import solver as solver_mod
    from wresdyn.sim.warmup import compile_kernels

    if args.min_len is not None:
        codegen.outline = functools.partial(codegen.outline, min_len=args.min_len)
    if args.inline is not None or args.opt_level is not None:
        hint = {"1": True, "0": False, "none": None, None: "solver"}[args.inline]
        solver_mod.generate_source = functools.partial(_variant, codegen.generate_source, hint, args.opt_level)
    wp.init()
    rt, dev = wp._src.context.runtime, wp.get_device(args.device)
    if args.split and not dev.is_cuda:
        sys.exit("--split needs a CUDA device")
    print(f"Warp {wp.__version__}: toolkit {rt.toolkit_version}, driver {rt.driver_version}, {dev.name} sm_{dev.arch}: "
          f"Warp compiles to {dev.get_cuda_output_format()} by default; CUDA_CACHE_DISABLE="
          f"{os.environ.get('CUDA_CACHE_DISABLE', '(unset)')}; load {load_average()}", flush=True)
    robot = load_robot(DEFAULT_ROBOT)
    t = time.perf_counter()
    compile_kernels(robot, 500.0, ("forward", "param_grads"), device=args.device)
    opt = "default" if args.opt_level is None else args.opt_level
    print(f"compile_kernels (forward, param_grads), inline {args.inline or 'default'}, min_len "
          f"{args.min_len or 'default'}, optimization_level {opt}: {time.perf_counter() - t:.1f} s; load {load_average()}",
          flush=True)
    if args.split:
        from wresdyn.sim import Simulator

        sim = Simulator(robot, 1, 1.0 / 500.0, device=args.device, requires_grad=True, param_grads=True)
        module = sim.solver.kernels.replay_step.module
        for fmt in ("ptx", "cubin"):
            t, c = time.perf_counter(), time.process_time()
            wp.compile_aot_module(module, arch=dev.arch, module_dir=str(scratch / f"aot_{fmt}"), use_ptx=fmt == "ptx")
            print(f"adjoint replay_step ahead of time to {fmt}: {time.perf_counter() - t:.1f} s wall, "
                  f"{time.process_time() - c:.1f} CPU-s; load {load_average()}", flush=True)
    if args.identify:
        sys.argv = [str(ROOT / "benchmarks" / "profile_identify.py"), "--device", args.device, "--fused"]
        runpy.run_path(sys.argv[0], run_name="__main__")


def _variant(generate, hint, opt, tree, scalar="float32", backward=True, inline=None, **kw):
    """The solver's source with the chunks' inline hint replaced (``"solver"``: kept) and, for the adjoint module, an
    ``optimization_level`` module option."""
    src = generate(tree, scalar, backward, inline=inline if hint == "solver" else hint, **kw)
    return with_opt_level(src, opt) if backward else src


if __name__ == "__main__":
    main()
