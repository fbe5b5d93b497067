"""SolverReplay's adjoint as one kernel or as a chain of pieces (``SolverReplay(adjoint_pieces=)``), checked.

    python benchmarks/speed/adjoint_pieces.py check [--device cuda:0] [--pieces 400] [--worlds 64] [--steps 20]

``check``: the humanoid's fused rollout under a Tape (friction solve on, per-world perturbed inputs), gradients to the
start state, targets, residual torques and every parameter array, with the adjoint as one kernel and in pieces:
prints each gradient's largest difference against its scale, and the wall-clock of one backward each way. Whole
commands run either way with ``WRESDYN_ADJOINT_PIECES=0`` (one kernel) or ``=400`` (pieces) in their environment.
"""

from __future__ import annotations

import sys
import time


def check(argv: list[str]) -> None:
    import argparse

    import numpy as np
    import warp as wp

    from wresdyn.robot.description import DEFAULT_ROBOT, load_robot
    from wresdyn.sim.solver_replay import SolverReplay
    from wresdyn.sim.solver_replay.kernels import ADJOINT_PIECES

    p = argparse.ArgumentParser(prog="adjoint_pieces.py check")
    p.add_argument("--device", default="cpu")
    p.add_argument("--pieces", type=int, default=ADJOINT_PIECES)
    p.add_argument("--worlds", type=int, default=64)
    p.add_argument("--steps", type=int, default=20)
    args = p.parse_args(argv)
    wp.config.quiet = True
    robot = load_robot(DEFAULT_ROBOT)
    w, t_len = args.worlds, args.steps
    params = ("body_mass", "body_com", "body_inertia", "joint_friction", "joint_armature", "joint_damping",
              "joint_target_ke", "joint_target_kd")

    def run(pieces: int) -> tuple[dict, float]:
        model = robot.build_model(w, args.device, requires_grad=True)
        s = SolverReplay(model, adjoint_pieces=pieces, friction_grad=True)
        n = s.tree.dofs_per_world
        rng = np.random.default_rng(1)
        q0 = np.concatenate([rng.uniform(-0.2, 0.2, (1, w, n)), np.zeros((t_len, w, n))]).astype(np.float32)
        q = wp.array(q0, requires_grad=True, device=args.device)
        qd = wp.zeros((t_len + 1, w, n), requires_grad=True, device=args.device)
        tq = wp.array(rng.uniform(-0.3, 0.3, (t_len, w, n)).astype(np.float32), requires_grad=True, device=args.device)
        jf = wp.array(rng.normal(size=(t_len, w, n)).astype(np.float32), requires_grad=True, device=args.device)
        seed = np.zeros((t_len + 1, w, n), np.float32)
        seed[t_len] = rng.normal(size=(w, n))
        best = float("inf")
        for _ in range(3):  # the first backward loads modules; the best of three is the figure
            tape = wp.Tape()
            with tape:
                s.rollout(q, qd, tq, 0.002, joint_f=jf)
            wp.synchronize_device(args.device)
            t0 = time.perf_counter()
            q.grad.zero_()
            q.grad.assign(seed)  # into the gradient array the launches were recorded with
            tape.backward()
            wp.synchronize_device(args.device)
            best = min(best, time.perf_counter() - t0)
            out = {"q_end": q.numpy()[t_len], "q0": q.grad.numpy()[0], "qd0": qd.grad.numpy()[0],
                   "target_q": tq.grad.numpy(), "joint_f": jf.grad.numpy(),
                   **{name: getattr(model, name).grad.numpy() for name in params}}
            out = {k: v.copy() for k, v in out.items()}  # a CPU array's numpy() is a view: zeroed below
            tape.zero()
            for name in params:
                getattr(model, name).grad.zero_()
        return out, best

    ref, t_one = run(0)
    got, t_pieces = run(args.pieces)
    print(f"humanoid, {w} worlds, {t_len} steps, {args.device}: backward one kernel {t_one * 1e3:.1f} ms, "
          f"pieces of {args.pieces} {t_pieces * 1e3:.1f} ms")
    worst = 0.0
    for k, v in ref.items():
        diff, scale = float(np.abs(got[k] - v).max()), float(np.abs(v).max())
        worst = max(worst, diff / max(scale, 1e-30))
        print(f"  {k:16s} max |difference| {diff:.3g}  (largest value {scale:.3g})")
    print(f"largest difference relative to its gradient's scale: {worst:.2g}")


def main() -> None:
    if len(sys.argv) < 2 or sys.argv[1] != "check":
        sys.exit(__doc__)
    check(sys.argv[2:])


if __name__ == "__main__":
    main()
