"""NVRTC sm_90 CUBIN of each module of the humanoid's adjoint in pieces (and its forward step), side by side in WORKERS
threads, on the CPU: ``PYTHONPATH=. python benchmarks/results/compile/pieces_nvrtc.py PIECES [WORKERS]`` (0 workers:
only count the pieces). Fresh Warp and generated-kernel caches in a temporary folder."""
import os, sys, tempfile, time
from concurrent.futures import ThreadPoolExecutor
L = int(sys.argv[1]); workers = int(sys.argv[2]) if len(sys.argv) > 2 else 2
scratch = tempfile.mkdtemp(prefix=f"pc{L}_")
os.environ["WRESDYN_KERNEL_DIR"] = scratch + "/src"
import warp as wp
wp.config.quiet = True
wp.config.kernel_cache_dir = scratch + "/wc"
wp.init()
from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
from wresdyn.sim import Simulator
from wresdyn.sim.solver_replay.codegen import generate_source
from wresdyn.sim.solver_replay.cache import load_module
robot = load_robot(DEFAULT_ROBOT)
solver = Simulator(robot, 1, 0.002, device="cpu", requires_grad=True, param_grads=True).solver
src = generate_source(solver.tree, "float32", True, inline=True, friction_sweeps=8, servo=None, pieces=L)
mod = load_module(src)
print("pieces", len(mod.PIECES), "slots", mod.PIECE_SLOTS, "lines", src.count("\n"), flush=True)
if workers == 0: sys.exit()
def comp(k):
    t = time.perf_counter(); c = time.thread_time()
    wp.compile_aot_module(k.module, arch=90)
    return k.key, time.perf_counter() - t, time.thread_time() - c
t0 = time.perf_counter(); c0 = time.process_time()
with ThreadPoolExecutor(workers) as ex:
    for key, w, c in ex.map(comp, list(mod.PIECES) + [mod.replay_step]):
        print(f"  {key}: {w:.1f} s wall {c:.1f} CPU-s", flush=True)
print(f"all: {time.perf_counter()-t0:.1f} s wall {time.process_time()-c0:.1f} CPU-s")
