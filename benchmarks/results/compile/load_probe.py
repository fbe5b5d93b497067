"""Time an in-process CUDA load (NVRTC compile + module load) of the humanoid's adjoint replay_step module."""
import sys, time
import warp as wp
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim.solver_replay.cache import load_module
from wresdyn.sim.solver_replay.codegen import generate_source
from wresdyn.sim.solver_replay.tree import tree_from_model
mode = sys.argv[1]
wp.init()
robot = load_robot(DEFAULT_ROBOT)
tree = tree_from_model(robot.build_model(1, "cpu"))
src = generate_source(tree, "float32", True, inline=True, friction_sweeps=8)
mod = load_module(src)
t0, c0 = time.perf_counter(), time.process_time()
if mode == "aot":
    import tempfile
    wp.compile_aot_module(mod.replay_step.module, arch=90, module_dir=tempfile.mkdtemp())
else:
    wp.load_module(mod.replay_step.module, device="cuda:0")
print(f"{mode}: {time.perf_counter() - t0:.1f} s wall, {time.process_time() - c0:.1f} CPU-s", flush=True)
