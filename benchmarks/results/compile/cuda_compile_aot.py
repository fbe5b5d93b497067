"""NVRTC compile time of SolverReplay's CUDA kernels for the humanoid, ahead of time (no GPU needed: Warp's
``compile_aot_module`` for sm_90, the H100/H200 architecture), in CPU-seconds and wall-clock.

usage: cuda_compile_aot.py TAG KERNEL [OPT_LEVEL|-]   KERNEL: step (the adjoint module's replay_step, forward +
backward, what the first fit waits for) or rollout (the forward module's). OPT_LEVEL: Warp's ``optimization_level``
module option ('-': Warp's CUDA default, -O3). Run with an empty WARP_CACHE_PATH and WRESDYN_KERNEL_DIR.
"""
import sys
import tempfile
import time

import warp as wp

wp.config.quiet = True
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot  # noqa: E402
from wresdyn.sim.solver_replay.cache import load_module  # noqa: E402
from wresdyn.sim.solver_replay.codegen import generate_source  # noqa: E402
from wresdyn.sim.solver_replay.tree import tree_from_model  # noqa: E402

tag, kernel = sys.argv[1], sys.argv[2]
opt = sys.argv[3] if len(sys.argv) > 3 else "-"
wp.init()
robot = load_robot(DEFAULT_ROBOT)
tree = tree_from_model(robot.build_model(1, "cpu"))
src = generate_source(tree, "float32", kernel == "step", inline=True, friction_sweeps=8)  # the solver's CUDA choice
if opt != "-":
    for flag in ("True", "False"):
        src = src.replace(f'@wp.kernel(enable_backward={flag}, module="unique")',
                          f'@wp.kernel(enable_backward={flag}, module="unique", module_options={{"optimization_level": {int(opt)}}})')
mod = load_module(src)
k = mod.replay_step if kernel == "step" else mod.replay_rollout
t0, c0 = time.perf_counter(), time.process_time()
wp.compile_aot_module(k.module, arch=90, module_dir=tempfile.mkdtemp())
print(f"{tag}: NVRTC sm_90 compile of replay_{kernel} ({'forward + backward' if kernel == 'step' else 'forward'}, "
      f"optimization_level {opt}): {time.perf_counter() - t0:.1f} s wall, {time.process_time() - c0:.1f} CPU-s", flush=True)
