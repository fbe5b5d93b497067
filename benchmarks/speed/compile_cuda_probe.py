"""The GPU's compile of SolverReplay's adjoint, measured on the CPU: NVRTC for sm_90 (H100/H200) ahead of time, for
a choice of how the step's outlined chunks are inlined and how large they are.

    python benchmarks/speed/compile_cuda_probe.py TAG [--inline 1|0|none] [--min-len N] [--output cubin|ptx] [--opt-level N]

Compiles the adjoint module's ``replay_step`` (forward + backward kernels; the humanoid, 8 friction sweeps, as
``wresdyn fit`` builds it) with Warp's ``compile_aot_module``. ``--output cubin`` is NVRTC and ptxas, the whole
compile a first run waits for: Warp hands the driver PTX on a driver at least as new as its toolkit, and the driver
runs ptxas on it at load; ``ptx`` is NVRTC's front end alone, so cubin minus ptx is ptxas. ``--inline``: the
``@wp.func`` hint of the chunks (``1``: force-inlined, the solver's CUDA choice; ``0``: kept out of line; ``none``:
NVRTC decides); ``--min-len``: the chunks' size in statements (``emit.outline``); ``--opt-level``: Warp's
``optimization_level`` module option (NVRTC's ``-O``). Every run uses its own fresh Warp
and generated-kernel caches. Prints one line: wall-clock and CPU-seconds (NVRTC runs in this process, one thread),
the load average before and after, and the output's size (and the PTX's functions); ``--keep`` copies the output.
"""

from __future__ import annotations

import argparse
import functools
import os
import shutil
import sys
import tempfile
import time
from pathlib import Path


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("tag")
    p.add_argument("--inline", default="1", choices=("1", "0", "none"))
    p.add_argument("--min-len", type=int, default=None, help="chunk size in statements (default: emit.outline's)")
    p.add_argument("--output", default="cubin", choices=("cubin", "ptx"))
    p.add_argument("--opt-level", type=int, default=None,
                   help="Warp's optimization_level module option for the module (default: Warp's, -O3 on CUDA)")
    p.add_argument("--arch", type=int, default=90)
    p.add_argument("--keep", default=None, help="copy the PTX or cubin here (e.g. to time ptxas on it alone)")
    in_scratch("cuda_probe_", run, p.parse_args())


def in_scratch(prefix: str, run, args) -> None:
    """``run(args, scratch)`` with a fresh scratch folder that holds the generated-kernel cache (and whatever ``run``
    puts there), deleted afterwards; ``args.min_len`` checked first."""
    if args.min_len is not None and args.min_len < 1:
        sys.exit("--min-len must be >= 1")
    scratch = Path(tempfile.mkdtemp(prefix=prefix))
    os.environ["WRESDYN_KERNEL_DIR"] = str(scratch / "src")
    try:
        run(args, scratch)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)


def with_opt_level(src: str, opt: int | None) -> str:
    """Generated source ``src`` with Warp's ``optimization_level`` module option ``opt`` on its adjoint module's
    kernels (``None``: unchanged)."""
    if opt is None:
        return src
    head = '@wp.kernel(enable_backward=True, module="unique"'
    return src.replace(head, head + f', module_options={{"optimization_level": {opt}}}')


def load_average() -> str:
    """The 1, 5 and 15 minute load averages (the cores are shared: every timing prints them)."""
    return " ".join(open("/proc/loadavg").read().split()[:3])


def run(args, scratch: Path) -> None:
    import warp as wp

    wp.config.quiet = True
    wp.config.kernel_cache_dir = str(scratch / "warp")
    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim.solver_replay import codegen
    from wresdyn.sim.solver_replay.cache import load_module
    from wresdyn.sim.solver_replay.solver import FRICTION_SWEEPS
    from wresdyn.sim.solver_replay.tree import tree_from_model

    if args.min_len is not None:
        codegen.outline = functools.partial(codegen.outline, min_len=args.min_len)
    inline = {"1": True, "0": False, "none": None}[args.inline]
    wp.init()
    tree = tree_from_model(load_robot(DEFAULT_ROBOT).build_model(1, "cpu"))
    src = codegen.generate_source(tree, "float32", True, inline=inline, friction_sweeps=FRICTION_SWEEPS)
    src = with_opt_level(src, args.opt_level)
    module = load_module(src).replay_step.module
    chunks = src.split("def replay_step(")[0].count("@wp.func")
    load0 = load_average()
    t0, c0 = time.perf_counter(), time.process_time()
    paths = wp.compile_aot_module(module, arch=args.arch, module_dir=str(scratch / "aot"), use_ptx=args.output == "ptx")
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    load1 = load_average()
    out = Path(paths[-1])
    if args.keep:
        shutil.copyfile(out, args.keep)
    extra = ""
    if args.output == "ptx":
        text = out.read_text()
        extra = f", {text.count('.func ')} .func in the PTX, {text.count(chr(10)) // 1000}k PTX lines"
    opt = "default" if args.opt_level is None else args.opt_level
    print(f"{args.tag}: NVRTC sm_{args.arch} {args.output} of the adjoint replay_step (inline {args.inline}, "
          f"min_len {args.min_len or 'default'}, {chunks} chunks, optimization_level {opt}): {wall:.1f} s wall, "
          f"{cpu:.1f} CPU-s; "
          f"{out.stat().st_size / 1e6:.2f} MB{extra}; load {load0} -> {load1}", flush=True)


if __name__ == "__main__":
    main()
