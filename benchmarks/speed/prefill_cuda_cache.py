"""Fill a Warp kernel cache with a robot's SolverReplay CUBINs for a GPU architecture, on any machine (no GPU needed:
NVRTC runs on the CPU), so that a first run on such a GPU loads them instead of compiling.

    WARP_CACHE_PATH=DIR python benchmarks/speed/prefill_cuda_cache.py [--arch 90] [--robot PATH]

Generates the replay modules a CUDA run of the robot builds (the forward and the adjoint variant, as
``SolverReplay`` generates them on CUDA: force-inlined chunks, the robot's friction sweeps and servo DoFs) and
compiles the module of each of their kernels (``replay_step``, ``replay_rollout``, ``replay_terms`` and the adjoint's
pieces ``replay_piece_<c>``) with Warp's
``compile_aot_module`` into the kernel cache (``WARP_CACHE_PATH``), where Warp looks for them:
``<module>.sm<arch>.cubin`` and its ``.meta``, the files a GPU run whose Warp compiles CUBIN (a driver older than
Warp's toolkit) writes itself.
Prints the CPU-seconds of each module. Warp's own and Newton's kernels are not included (they compile in seconds).
"""

from __future__ import annotations

import argparse
import time


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--arch", type=int, default=90, help="compute capability, e.g. 90 for H100/H200")
    p.add_argument("--robot", default=None, help="robot file (default: the shipped humanoid)")
    p.add_argument("--pieces", type=int, default=None,
                   help="statements per adjoint kernel (default: SolverReplay's on CUDA; 0: the adjoint as one kernel)")
    args = p.parse_args()
    import warp as wp

    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim import Simulator
    from wresdyn.sim.solver_replay.kernels import ADJOINT_PIECES, load_kernels

    wp.config.quiet = True
    wp.init()
    robot = load_robot(args.robot or DEFAULT_ROBOT)
    # a one-world CPU simulator only to read the solver's structural settings (nothing of it runs on the GPU)
    solver = Simulator(robot, 1, 0.002, device="cpu", requires_grad=True, param_grads=True).solver
    if not hasattr(solver, "tree"):
        raise SystemExit(f"{robot.source}: its simulator does not use SolverReplay; nothing to prefill")
    sweeps = solver.friction_sweeps if solver.friction_kappa != 0.0 else 0
    done: list = []
    for backward in (False, True):
        pieces = ADJOINT_PIECES if args.pieces is None else args.pieces
        kernels = load_kernels(solver.tree, "float32", backward, True, sweeps, solver.servo, pieces)
        for kernel in (kernels.replay_step, kernels.replay_rollout, kernels.replay_terms,
                       *getattr(kernels, "PIECES", ())):
            module = kernel.module
            if any(module is m for m in done):
                continue
            done.append(module)
            t, c = time.perf_counter(), time.process_time()
            paths = wp.compile_aot_module(module, arch=args.arch)
            print(f"{'adjoint' if backward else 'forward'} {kernel.key}: {time.perf_counter() - t:.1f} s wall, "
                  f"{time.process_time() - c:.1f} CPU-s -> {paths[-1]}", flush=True)


if __name__ == "__main__":
    main()
