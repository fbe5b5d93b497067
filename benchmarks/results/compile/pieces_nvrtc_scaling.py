"""How NVRTC's compiles of the humanoid's adjoint pieces (and forward step and rollout) scale over threads and over
processes on one host: ``python benchmarks/results/compile/pieces_nvrtc_scaling.py MODE WORKERS`` with MODE
``thread`` (Warp's way: one process, a thread per module) or ``process`` (one process per module, each generating
the source itself); fresh Warp and generated-kernel caches. Prints the wall-clock of all 14 modules."""
import os
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor


def modules():
    import warp as wp

    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim import Simulator
    from wresdyn.sim.solver_replay.kernels import load_kernels

    wp.config.quiet = True
    wp.init()
    s = Simulator(load_robot(DEFAULT_ROBOT), 1, 0.002, device="cpu", requires_grad=True, param_grads=True).solver
    k = load_kernels(s.tree, "float32", True, True, 8, None, 400)
    return [x.module for x in (k.replay_step, k.replay_rollout, *k.PIECES)]


def one(i):
    import warp as wp

    t = time.perf_counter()
    wp.compile_aot_module(modules()[i], arch=90)
    return time.perf_counter() - t


def main():
    mode, workers = sys.argv[1], int(sys.argv[2])
    scratch = tempfile.mkdtemp(prefix="nvscale_")
    os.environ["WRESDYN_KERNEL_DIR"] = scratch + "/src"
    os.environ["WARP_CACHE_PATH"] = scratch + "/wc"
    n = len(modules())
    t = time.perf_counter()
    if mode == "thread":
        import warp as wp

        mods = modules()
        with ThreadPoolExecutor(workers) as ex:
            times = list(ex.map(lambda m: (lambda t0: (wp.compile_aot_module(m, arch=90), time.perf_counter() - t0)[1])(
                time.perf_counter()), mods))
    else:
        with ProcessPoolExecutor(workers) as ex:
            times = list(ex.map(one, range(n)))
    print(f"{mode} x {workers}: {n} modules in {time.perf_counter() - t:.1f} s wall; each {min(times):.1f}-"
          f"{max(times):.1f} s, sum {sum(times):.1f} s", flush=True)


if __name__ == "__main__":
    main()
