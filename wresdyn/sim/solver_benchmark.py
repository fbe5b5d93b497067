"""Solver benchmark behind ``wresdyn bench``: env-steps/s of the replay workload, every solver, same robot and worlds.

One world is one robot on a stand under PD, no contacts, ``dt`` = 2 ms; an env-step is one world
advanced by one ``dt``. Rows (each where the device allows):

- ``replay rollout``: :meth:`SolverReplay.rollout`, T steps fused in one launch (per CPU thread);
  forward+backward is a Tape over a ``--horizon`` window (fused forward, per-step adjoint).
- ``replay step``: :meth:`SolverReplay.step` in a Python loop, as Newton code calls a solver;
  forward+backward is a Tape over ``--horizon`` steps with one state per step.
- ``featherstone``: Newton ``SolverFeatherstone``, same loops as ``replay step``.
- ``mujoco-warp``: Newton ``SolverMuJoCo`` on mujoco_warp (CUDA only, not differentiable).
- ``mujoco-c``: MuJoCo C ``mj_step`` through ``mujoco.rollout`` with ``--threads`` threads (CPU).

On CUDA every loop is captured once in a CUDA graph and replayed. Ratios are against ``featherstone``
and ``mujoco-c`` in the same run. Targets: a sinusoid per joint for the rollouts, held fixed in the step
loops (the state still moves: it starts away from the target).

The replay rows run the kernels the fits run: SolverReplay with the settings :class:`~wresdyn.sim.Simulator` gives it
(friction law and sweeps, no friction gradient, branch lanes and block size of
:mod:`~wresdyn.sim.solver_replay.kernels`), and by default (``--adjoint auto``) the adjoint form a fit would take on
this machine now: on CUDA the one kernel where Warp's cache holds it, else the pieces, with the one kernel compiling
in the background (a later row may then switch to it). Each forward + backward row prints the form it timed.
"""

from __future__ import annotations

import functools
import json
import time

from ..robot.description import DEFAULT_ROBOT, load_robot
from ..robot.mujoco_model import build_mujoco
from .devices import require_device
from .solver_replay.kernels import ADJOINT_PIECES, background_compiles, branch_lanes, cuda_launch

__all__ = ["SOLVERS", "run_bench"]

SOLVERS = ("replay", "featherstone", "mujoco-warp", "mujoco-c")
"""Rows of the benchmark (see the module docstring)."""


@functools.cache
def _loss_kernel():
    """Sum of squares of a flat array into ``loss[0]``: the scalar the Tape measurements differentiate."""
    import warp as wp

    @wp.kernel
    def sum_sq(x: wp.array(dtype=float), loss: wp.array(dtype=float)):
        i = wp.tid()
        wp.atomic_add(loss, 0, x[i] * x[i])

    return sum_sq


def _rate(fn, env_steps: int, sync, min_time: float) -> float:
    """Env-steps/s of ``fn`` (one warm-up call, then repeated for at least ``min_time`` seconds)."""
    fn()
    sync()
    n, t0 = 0, time.perf_counter()
    while True:
        fn()
        n += 1
        sync()
        el = time.perf_counter() - t0
        if el >= min_time:
            return n * env_steps / el


class _Bench:
    def __init__(self, args, robot):
        import numpy as np
        import warp as wp

        self.wp, self.np, self.args, self.robot = wp, np, args, robot
        self.cuda = str(args.device).startswith("cuda")
        self.n = robot.n_dof
        span = np.where(np.isfinite(robot.upper - robot.lower), robot.upper - robot.lower, 2.0)
        lo = np.where(np.isfinite(robot.lower), robot.lower, -1.0)
        hi = np.where(np.isfinite(robot.upper), robot.upper, 1.0)
        self.q0 = np.clip(np.zeros(self.n), lo + 0.3 * span, hi - 0.3 * span)
        self.amp = np.minimum(0.2, 0.12 * span)
        self.forms: dict[tuple[str, int], str] = {}  # (row, worlds) -> the adjoint form a backward row timed

    def replay(self, model, row: str, w: int):
        """SolverReplay as the fits' Simulator builds it, the adjoint in the form ``--adjoint`` asks for; records the
        form for the row."""
        from .solver_replay import SolverReplay

        pieces = {"auto": None, "one": 0, "pieces": ADJOINT_PIECES}[getattr(self.args, "adjoint", "auto")]
        solver = SolverReplay(model, threads=self.args.threads, friction_grad=False, adjoint_pieces=pieces)
        if solver.requires_grad:
            n = len(getattr(solver.kernels, "PIECES", ()))
            form = f"{n} kernels of ~{solver.adjoint_pieces} statements" if solver.adjoint_pieces else "one kernel"
            later = " (one kernel compiling in the background)" if background_compiles() else ""
            self.forms[(row, w)] = form + later
        return solver

    def sync(self):
        self.wp.synchronize_device(self.args.device)

    def graph(self, fn):
        """On CUDA: capture ``fn`` once and return a replay of the graph; on CPU ``fn`` itself."""
        if not self.cuda:
            return fn
        wp = self.wp
        fn()  # allocations and compilation happen outside the capture
        with wp.ScopedCapture(device=self.args.device) as cap:
            fn()
        return lambda: wp.capture_launch(cap.graph)

    def targets(self, t_len: int, w: int):
        np = self.np
        t = np.arange(t_len)[:, None, None] * self.args.dt
        f = np.linspace(0.3, 1.0, self.n)[None, None, :]
        return (self.q0 + self.amp * np.sin(2 * np.pi * f * t + np.arange(w)[None, :, None] * 0.1)).astype(np.float32)

    def states(self, model, w: int, count: int, requires_grad: bool):
        np = self.np
        states = [model.state(requires_grad=requires_grad) for _ in range(count)]
        nq = model.joint_coord_count // w
        jq = np.zeros((w, nq), dtype=np.float32)
        jq[:, self.robot.q_index] = self.q0 + 0.1
        states[0].joint_q.assign(jq.ravel())
        return states

    def control(self, model, w: int, requires_grad: bool = False):
        np = self.np
        ctrl = model.control(requires_grad=requires_grad)
        nqd = model.joint_dof_count // w
        tq = np.zeros((w, nqd), dtype=np.float32)
        tq[:, self.robot.qd_index] = self.q0
        ctrl.joint_target_q.assign(tq.ravel())
        return ctrl

    # -------------------------------------------------------------- Newton solvers, step API
    def step_api(self, make, w: int, steps: int, backward: bool):
        wp, args = self.wp, self.args
        model = self.robot.build_model(w, args.device, requires_grad=backward)
        solver = make(model)
        if not backward:
            s = self.states(model, w, 2, False)
            ctrl = self.control(model, w)

            def fwd():
                a, b = s
                for _ in range(steps):
                    solver.step(a, b, ctrl, None, args.dt)
                    a, b = b, a
            return _rate(self.graph(fwd), w * steps, self.sync, args.min_time)
        h = args.horizon
        s = self.states(model, w, h + 1, True)
        ctrl = self.control(model, w, True)
        loss = wp.zeros(1, dtype=float, device=args.device, requires_grad=True)
        kernel = _loss_kernel()
        tape = wp.Tape()

        def fwd_bwd():
            with tape:
                for k in range(h):
                    solver.step(s[k], s[k + 1], ctrl, None, args.dt)
                wp.launch(kernel, dim=s[h].joint_q.shape[0], inputs=[s[h].joint_q], outputs=[loss], device=args.device)
            tape.backward(loss)
            tape.zero()
            tape.reset()
            loss.zero_()
        return _rate(self.graph(fwd_bwd), w * h, self.sync, args.min_time)

    # -------------------------------------------------------------- SolverReplay rollout
    def rollout(self, w: int, backward: bool):
        wp, args, n = self.wp, self.args, self.n
        model = self.robot.build_model(w, args.device, requires_grad=backward)
        # gradients to states and controls, as residual learning takes them (Simulator(param_grads=False))
        solver = self.replay(model, "replay rollout", w)
        t_len = args.horizon if backward else args.steps
        tr = solver.tree
        if tr.coords_per_world != n or tr.dofs_per_world != n:
            raise ValueError("the rollout benchmark needs every joint coordinate actuated")
        tq = wp.array(self.targets(t_len, w)[:, :, self.robot.qd_index.argsort()], dtype=float, device=args.device,
                      requires_grad=backward)
        q = wp.zeros((t_len + 1, w, n), dtype=float, device=args.device, requires_grad=backward)
        qd = wp.zeros((t_len + 1, w, n), dtype=float, device=args.device, requires_grad=backward)
        q0 = self.np.zeros((t_len + 1, w, n), dtype=self.np.float32)
        q0[0] = self.q0[self.robot.q_index.argsort()] + 0.1
        q.assign(q0)
        if not backward:
            return _rate(self.graph(lambda: solver.rollout(q, qd, tq, args.dt)), w * t_len, self.sync, args.min_time)
        jf = wp.zeros((t_len, w, n), dtype=float, device=args.device, requires_grad=True)
        loss = wp.zeros(1, dtype=float, device=args.device, requires_grad=True)
        kernel = _loss_kernel()
        last = q[t_len].flatten()
        tape = wp.Tape()

        def fwd_bwd():
            with tape:
                solver.rollout(q, qd, tq, args.dt, joint_f=jf)
                wp.launch(kernel, dim=w * n, inputs=[last], outputs=[loss], device=args.device)
            tape.backward(loss)
            tape.zero()
            tape.reset()
            loss.zero_()
        return _rate(self.graph(fwd_bwd), w * t_len, self.sync, args.min_time)

    # -------------------------------------------------------------- MuJoCo C
    def mujoco_c(self, w: int):
        import mujoco
        from mujoco import rollout

        np, args = self.np, self.args
        m = build_mujoco(self.robot, args.dt, "implicitfast")
        d = mujoco.MjData(m)
        d.qpos[:] = self.q0 + 0.1
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.zeros(mujoco.mj_stateSize(m, spec))
        mujoco.mj_getState(m, d, state, spec)
        init = np.repeat(state[None], w, axis=0)
        ctrl = self.targets(args.steps, w).transpose(1, 0, 2).astype(np.float64)
        threads = max(1, args.threads)
        datas = [mujoco.MjData(m) for _ in range(threads)]
        out = np.zeros((w, args.steps, state.size))
        with rollout.Rollout(nthread=threads if threads > 1 else 0) as pool:
            return _rate(lambda: pool.rollout(m, datas, init, ctrl, state=out), w * args.steps, lambda: None,
                         args.min_time)


def run_bench(args) -> int:
    """Run the benchmark for the parsed ``wresdyn bench`` arguments; prints the table (and writes ``--json``)."""
    import warp as wp

    wp.config.quiet = True
    robot = load_robot(args.robot or DEFAULT_ROBOT, gains=args.gains)
    robot.check_gains()
    require_device(args.device)
    cuda = str(args.device).startswith("cuda")
    worlds = [int(x) for x in (args.worlds or ("1024,4096,16384" if cuda else "1,16,128")).split(",")]
    solvers = args.solvers
    b = _Bench(args, robot)

    def replay_solver(w):
        return lambda model: b.replay(model, "replay step", w)

    def featherstone(model):
        import newton

        return newton.solvers.SolverFeatherstone(model)

    def mujoco_warp(model):
        import newton

        return newton.solvers.SolverMuJoCo(model, use_mujoco_cpu=False, disable_contacts=True,
                                           integrator="implicitfast")

    rows: dict[str, dict[int, tuple[float | None, float | None]]] = {}
    for w in worlds:
        def put(name, fwd, bwd):
            rows.setdefault(name, {})[w] = (fwd, bwd)
            form = b.forms.get((name, w))
            print(f"  {name:<16} worlds {w:>6}: fwd {_fmt(fwd):>9}  fwd+bwd {_fmt(bwd):>9}"
                  + (f"  (adjoint: {form})" if form else ""), flush=True)

        if "replay" in solvers:
            put("replay rollout", b.rollout(w, False), b.rollout(w, True))
            put("replay step", b.step_api(replay_solver(w), w, args.steps, False),
                b.step_api(replay_solver(w), w, args.horizon, True))
        if "featherstone" in solvers:
            bwd = b.step_api(featherstone, w, args.horizon, True) if w <= args.slow_max_worlds else None
            put("featherstone", b.step_api(featherstone, w, args.slow_steps, False), bwd)
        if "mujoco-warp" in solvers and cuda:
            put("mujoco-warp", b.step_api(mujoco_warp, w, args.steps, False), None)
        if "mujoco-c" in solvers:
            put("mujoco-c", b.mujoco_c(w), None)

    device = wp.get_device(args.device)
    config = _replay_config(cuda)
    print(f"\n{robot.source.name} ({robot.n_dof} DoF), dt {args.dt} s, device {device.alias} ({device.name}), "
          f"CPU threads {args.threads}, forward {args.steps} steps, fwd+bwd Tape horizon {args.horizon}, "
          f"CUDA graphs {'on' if cuda else 'n/a'}; env-steps/s")
    if "replay" in solvers:
        print(f"SolverReplay as the fits build it: {config['threads_per_world']}"
              + (f", blocks of {config['block_dim']} threads" if cuda else "")
              + f"; adjoint ({getattr(args, 'adjoint', 'auto')}): "
              + "; ".join(f"{name} at {w}: {form}" for (name, w), form in b.forms.items()))
    print()
    head = "| solver | " + " | ".join(f"{w} fwd | {w} fwd+bwd" for w in worlds) + " |"
    print(head)
    print("|" + "---|" * (1 + 2 * len(worlds)))
    for name, per in rows.items():
        print(f"| {name} | " + " | ".join(f"{_fmt(per[w][0])} | {_fmt(per[w][1])}" for w in worlds) + " |")
    for ref in ("featherstone", "mujoco-c"):
        if ref not in rows:
            continue
        for name in ("replay rollout", "replay step"):
            if name in rows:
                cells = []
                for w in worlds:
                    f, g = rows[name][w]
                    rf, rg = rows[ref][w]
                    cells += [_ratio(f, rf), _ratio(g, rg)]
                print(f"| {name} / {ref} | " + " | ".join(cells) + " |")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump({"robot": robot.source.name, "robot_sha256": robot.source_sha256, "device": str(device),
                       "device_name": device.name, "dt": args.dt, "threads": args.threads,
                       "steps": args.steps, "horizon": args.horizon, "replay": config,
                       "adjoint": {f"{name} {w}": form for (name, w), form in b.forms.items()},
                       "rows": {k: {str(w): v for w, v in per.items()} for k, per in rows.items()}}, fh, indent=1)
    return 0


def _replay_config(cuda: bool) -> dict:
    """The replay kernels' launch settings on this device, as the fits get them."""
    lanes = branch_lanes(cuda)
    return {"lanes": lanes, "block_dim": cuda_launch()[0] if cuda else None,
            "threads_per_world": "one thread per world and branch of the base" if lanes else "one thread per world"}


def _fmt(x: float | None) -> str:
    if x is None:
        return "n/a"
    return f"{x / 1e6:.2f}M" if x >= 1e6 else f"{x / 1e3:.1f}k"


def _ratio(a: float | None, b: float | None) -> str:
    return "n/a" if a is None or b is None or b == 0 else f"{a / b:.1f}x"
