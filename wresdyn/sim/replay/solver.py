"""``SolverReplay``: a Newton solver specialised for PD replay of fixed-base robots (issue 6).

The replay workload is one articulated robot per world, PD drives plus a residual torque, no contacts.
Newton's ``SolverFeatherstone`` handles it with ~20 kernel launches per step, a dense ``J^T M J`` mass
matrix and explicit PD (unstable at 500 Hz on light joints without armature). This solver runs a step in one
kernel, one thread per world, with code generated for the robot at hand (:mod:`.codegen`): RNEA bias,
CRBA mass matrix, a tree ``L^T D L`` factorisation and semi-implicit Euler, all differentiable by
Warp's Tape. Equation of one step (``H`` is the matrix the generated kernel factorises)::

    (M(q) + A + dt D + dt^2 K) qdd = tau_pd + joint_f - c(q, qd) - d qd + tau_fric + tau_lim - dt K qd
    qd' = qd + dt qdd,   q' = q + dt qd'

- ``A``: armature (``Model.joint_armature``) on the diagonal.
- ``tau_pd = clamp(ke (q* - q) + kd (qd* - qd), -effort, effort)``, the position actuator of eq. (1)
  of the paper (``Model.joint_target_ke/kd``, ``joint_effort_limit`` with 0 meaning unlimited,
  ``Control.joint_target_q/qd``).
- ``D``: velocity derivatives treated implicitly, as MuJoCo's ``implicitfast`` integrator does:
  drive ``kd`` while the drive is not saturated (a clamped force has no velocity derivative),
  passive damping ``d`` (``Model.joint_damping``), the friction slope and the limit damping.
- ``K``: position derivatives treated implicitly: the joint-limit stiffness always, the drive ``ke``
  only with ``implicit_stiffness=True`` (off by default to match ``implicitfast``).
- ``tau_fric = -mu tanh(qd / v_s)``: smoothed Coulomb friction (``Model.joint_friction``) with
  ``v_s = friction_vel`` (default 0.01 rad/s: tanh(3) = 0.995, so above 0.03 rad/s it is Coulomb
  friction to 0.5 %, far below the 0.1-1 rad/s joint speeds of the excitation trajectories). Its slope
  ``mu / v_s`` near rest would need dt < 2 I v_s / mu explicitly; it goes into ``D`` instead.
- ``tau_lim``: penalty ``limit_ke * violation - limit_kd * qd`` outside ``[lower, upper]``
  (``Model.joint_limit_*``); unlike Newton's semi-implicit convention the drive stays on at a limit.
- ``joint_f``: the residual torque ``tau_res`` of eq. (1), added unclamped.

Gradients (a ``wp.Tape`` around :meth:`step` or :meth:`rollout`, ``requires_grad``) reach the states,
targets and ``joint_f``, and, when the model was finalized with ``requires_grad``, the drive and joint
parameters above.

Not supported: floating bases, contacts, mimic joints, ``joint_target_mode`` (drives act wherever
``ke`` or ``kd`` is non-zero), velocity limits. ``State.body_q`` is only refreshed with
``update_body_q=True``.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np
import warp as wp
from newton import ModelFlags
from newton.solvers import SolverBase

from .cache import load_module
from .codegen import generate_source
from .tree import ReplayTree, tree_from_model

__all__ = ["SolverReplay"]


def _load_kernels(tree: ReplayTree, scalar: str, backward: bool, cuda: bool):
    """Generate and load (:func:`~.cache.load_module`) the kernel module for ``tree``.

    The step kernel's adjoint is outlined into non-inlined functions for Clang (CPU), where the whole step
    as one function compiled for two minutes (16 s outlined); NVRTC is the other way round (over ten
    minutes outlined at full optimisation, 45 s force-inlined), so CUDA inlines.
    """
    return load_module(generate_source(tree, scalar, backward, inline=bool(cuda)))


class SolverReplay(SolverBase):
    """Fused, differentiable reduced-coordinate solver for PD replay; a drop-in for ``SolverFeatherstone``.

    Example::

        solver = SolverReplay(model)
        for k in range(T):
            control.joint_target_q.assign(...)   # PD targets
            control.joint_f.assign(...)          # residual torque
            solver.step(state_0, state_1, control, None, dt)
            state_0, state_1 = state_1, state_0

    For open-loop replay of a whole command sequence, :meth:`rollout` runs ``T`` steps in one launch.
    """

    def __init__(
        self,
        model,
        *,
        friction_vel: float = 0.01,
        implicit_stiffness: bool = False,
        requires_grad: bool | None = None,
        update_body_q: bool = False,
        threads: int = 1,
        dtype=wp.float32,
    ):
        """
        Args:
            model: Newton model holding one identical fixed-base robot per world.
            friction_vel: Velocity scale ``v_s`` of the smoothed Coulomb friction [rad/s or m/s].
            implicit_stiffness: Also treat the drive stiffness implicitly (``dt^2 ke`` on the diagonal);
                more stable for very stiff drives, but no longer MuJoCo ``implicitfast`` parity.
            requires_grad: Compile adjoint kernels (default: ``model.requires_grad``).
            update_body_q: Refresh ``state_out.body_q/body_qd`` with ``newton.eval_fk`` after each step.
            threads: CPU only: split the worlds over this many host threads (Warp runs a CPU kernel's
                threads one after another; separate launches run concurrently).
            dtype: ``wp.float32`` (Newton's state arrays) or ``wp.float64`` (:meth:`rollout` only, for
                finite-difference checks).
        """
        super().__init__(model)
        if dtype not in (wp.float32, wp.float64):
            raise ValueError("dtype must be wp.float32 or wp.float64")
        self.friction_vel = float(friction_vel)
        self.implicit_stiffness = bool(implicit_stiffness)
        self.requires_grad = bool(model.requires_grad if requires_grad is None else requires_grad)
        self.update_body_q = bool(update_body_q)
        self.threads = max(1, int(threads)) if model.device.is_cpu else 1
        self.dtype = dtype
        self._pool = None
        self._plans: dict = {}
        self._zeros: dict = {}
        self._control0 = None
        self._build()

    # ------------------------------------------------------------------ set-up
    def _build(self) -> None:
        self.tree: ReplayTree = tree_from_model(self.model)
        scalar = "float64" if self.dtype == wp.float64 else "float32"
        self.kernels = _load_kernels(self.tree, scalar, self.requires_grad, self.model.device.is_cuda)
        self._refresh_params()

    def _refresh_params(self) -> None:
        self._plans.clear()  # recorded launches hold the parameter arrays
        m = self.model
        names = ("joint_target_ke", "joint_target_kd", "joint_armature", "joint_friction", "joint_damping",
                 "joint_effort_limit", "joint_limit_lower", "joint_limit_upper", "joint_limit_ke", "joint_limit_kd")
        if self.dtype == wp.float32:
            self._params = [getattr(m, n) for n in names]
            self._gravity = m.gravity
        else:
            self._params = [wp.array(getattr(m, n).numpy().astype(np.float64), dtype=wp.float64, device=m.device)
                            for n in names]
            self._gravity = wp.array(m.gravity.numpy().astype(np.float64), dtype=wp.vec3d, device=m.device)

    def notify_model_changed(self, flags: int) -> None:
        """Recompile after joint-frame or inertia edits; gains, limits, armature, friction and gravity are
        read live (float32) or re-copied (float64)."""
        rebuild = ModelFlags.JOINT_PROPERTIES | ModelFlags.BODY_INERTIAL_PROPERTIES
        if int(flags) & int(rebuild):
            self._build()
        else:
            self._refresh_params()

    # ------------------------------------------------------------------ launching
    def _scalars(self, dt: float) -> list:
        return [float(dt), self.friction_vel, 1.0 if self.implicit_stiffness else 0.0]

    def _chunks(self) -> list[tuple[int, int]]:
        w = self.tree.world_count
        n = min(self.threads, w)
        edges = np.linspace(0, w, n + 1).astype(int)
        return [(int(a), int(b - a)) for a, b in zip(edges[:-1], edges[1:]) if b > a]

    def _plan(self, key: tuple, build):
        """Per-chunk lists of launch callables, built once per argument signature ``key``.

        A CPU ``wp.launch`` with ~30 arguments costs tens of microseconds of Python, more than a step of a
        few worlds, so launches are recorded once (``record_cmd``) and replayed; the signature holds the
        arrays' addresses, so new arrays get a new plan.
        """
        plan = self._plans.get(key)
        if plan is None:
            if len(self._plans) >= 256:
                self._plans.clear()
            plan = self._plans[key] = [build(chunk) for chunk in self._chunks()]
        return plan

    def _command(self, kernel, chunk: tuple[int, int], args: list, outputs: list, adjoint: bool = False):
        """A callable that launches ``kernel(world_start, *args, *outputs)`` (or its adjoint) on one chunk."""
        inputs = [chunk[0], *args]
        extra = {}
        if adjoint:
            extra = {"adj_inputs": [_grad(a) for a in inputs], "adj_outputs": [_grad(a) for a in outputs]}
        cmd = wp.launch(kernel, dim=chunk[1], inputs=inputs, outputs=outputs, device=self.model.device,
                        adjoint=adjoint, record_cmd=True, **extra)
        return _cpu_call(cmd) or cmd.launch

    def _execute(self, plan: list) -> None:
        """Run each chunk's launches in order, the chunks concurrently (CPU threads)."""
        if len(plan) == 1:
            for call in plan[0]:
                call()
            return
        if self._pool is None:
            self._pool = ThreadPoolExecutor(max_workers=self.threads, thread_name_prefix="replay")
        list(self._pool.map(lambda calls: [call() for call in calls], plan))

    def _record(self, backward, arrays: list) -> None:
        """Under a recording ``wp.Tape``, register ``backward`` for the arrays that carry gradients."""
        tape = wp._src.context.runtime.tape
        if tape is None:
            return
        if not self.requires_grad:
            raise RuntimeError("SolverReplay under a wp.Tape needs requires_grad=True (model or solver argument)")
        tape.record_func(backward, [a for a in arrays if isinstance(a, wp.array) and a.requires_grad])

    # ------------------------------------------------------------------ Newton API
    def step(self, state_in, state_out, control, contacts, dt: float, *, observables=None) -> None:
        """Advance every world by ``dt``: reads ``state_in.joint_q/joint_qd`` and ``control.joint_target_q``,
        ``joint_target_qd``, ``joint_f``; writes ``state_out.joint_q/joint_qd``. ``contacts`` is ignored."""
        if self.dtype != wp.float32:
            raise RuntimeError("SolverReplay.step needs dtype=wp.float32 (Newton's state arrays); use rollout()")
        if control is None:
            if self._control0 is None:
                self._control0 = self.model.control()
            control = self._control0
        arrays = [state_in.joint_q, state_in.joint_qd, control.joint_target_q, control.joint_target_qd,
                  control.joint_f, state_out.joint_q, state_out.joint_qd]
        key = ("step", float(dt), *map(_sig, arrays))
        args, outputs = [*self._scalars(dt), *self._params, self._gravity, *arrays[:5]], arrays[5:]
        kernel = self.kernels.replay_step
        self._execute(self._plan(key, lambda c: [self._command(kernel, c, args, outputs)]))
        self._record(lambda: self._execute(self._plan(key + ("adjoint",), lambda c: [
            self._command(kernel, c, args, outputs, adjoint=True)])), args + outputs)
        if self.update_body_q:
            import newton

            newton.eval_fk(self.model, state_out.joint_q, state_out.joint_qd, state_out)

    def rollout(self, q: wp.array, qd: wp.array, target_q: wp.array, dt: float,
                target_qd: wp.array | None = None, joint_f: wp.array | None = None) -> None:
        """Run ``T`` steps of every world in one launch (per CPU thread).

        Trajectories are time-major, so row ``t`` has the layout of Newton's ``joint_q``/``joint_qd``.

        Args:
            q: Joint positions, shape (T + 1, worlds, coords per world); row 0 holds the initial state on
                entry, rows 1..T are written.
            qd: Joint velocities, shape (T + 1, worlds, dofs per world); same convention.
            target_q: PD position targets, shape (T, worlds, dofs per world); target ``t`` acts during step ``t``.
            dt: Time step [s].
            target_qd: PD velocity targets, same shape (default zero).
            joint_f: Residual/external joint torque, same shape (default zero).

        Arrays are in the solver's ``dtype`` on the model's device. Under a ``wp.Tape`` the forward runs
        fused and the backward runs the step kernel's adjoint for ``t = T-1 .. 0`` (needs
        ``requires_grad``); gradients reach ``q.grad[0]``, ``qd.grad[0]``, ``target_q.grad``,
        ``target_qd.grad``, ``joint_f.grad`` and, for a float32 model with gradients, the drive and
        joint parameters' ``.grad``.
        """
        t_len, w = target_q.shape[0], target_q.shape[1]
        tr = self.tree
        if (w != tr.world_count or q.shape != (t_len + 1, w, tr.coords_per_world)
                or qd.shape != (t_len + 1, w, tr.dofs_per_world) or target_q.shape[2] != tr.dofs_per_world):
            raise ValueError(f"rollout shapes: q {q.shape}, qd {qd.shape}, target_q {target_q.shape} do not match "
                             f"(T+1 | T, {tr.world_count} worlds, {tr.coords_per_world} coords / "
                             f"{tr.dofs_per_world} dofs)")
        if target_qd is None or joint_f is None:
            zeros = self._zeros.get(target_q.shape)
            if zeros is None:
                zeros = wp.zeros(target_q.shape, dtype=self.dtype, device=self.model.device)
                self._zeros[target_q.shape] = zeros
            target_qd = zeros if target_qd is None else target_qd
            joint_f = zeros if joint_f is None else joint_f
        arrays = [q, qd, target_q, target_qd, joint_f]
        key = ("rollout", float(dt), *map(_sig, arrays))
        fixed = [*self._scalars(dt), *self._params, self._gravity]
        kernel = self.kernels.replay_rollout
        self._execute(self._plan(key, lambda c: [self._command(kernel, c, [t_len, *fixed, *arrays[2:]], arrays[:2])]))
        if wp._src.context.runtime.tape is None:
            return

        def adjoints(chunk):
            # step t's adjoint reads the gradient of state t + 1 and adds into state t and step t's inputs;
            # row t of a time-major trajectory has Newton's flat layout, so the step kernel's adjoint applies
            rows = [[a[t].flatten() for t in range(a.shape[0])] for a in arrays]
            step = self.kernels.replay_step
            return [self._command(step, chunk, [*fixed, *(r[t] for r in rows)], [rows[0][t + 1], rows[1][t + 1]], True)
                    for t in reversed(range(t_len))]

        self._record(lambda: self._execute(self._plan(key + ("adjoint",), adjoints)), fixed + arrays)

    def dynamics_terms(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Mass matrix ``M(q)`` (without armature) and bias ``c(q, qd)`` (Coriolis, centrifugal, gravity) of
        world 0's robot at a batch of states, in DoF order; for tests. Shapes (B, n, n) and (B, n)."""
        q, qd = np.atleast_2d(q), np.atleast_2d(qd)
        b, n = q.shape[0], self.tree.n_dof
        dev = self.model.device
        dt = np.float64 if self.dtype == wp.float64 else np.float32
        m_out = wp.zeros((b, n, n), dtype=self.dtype, device=dev)
        c_out = wp.zeros((b, n), dtype=self.dtype, device=dev)
        g = wp.array(np.repeat(self._gravity.numpy()[:1], b, axis=0), dtype=self._gravity.dtype, device=dev)
        q_in = wp.array(q.astype(dt), dtype=self.dtype, device=dev)
        qd_in = wp.array(qd.astype(dt), dtype=self.dtype, device=dev)
        wp.launch(self.kernels.replay_terms, dim=b, inputs=[g, q_in, qd_in], outputs=[m_out, c_out], device=dev)
        return m_out.numpy(), c_out.numpy()


def _cpu_call(cmd):
    """A CPU launch as a direct call of the compiled entry point with argument structs built once.

    ``Launch.launch`` rebuilds the ctypes argument structs on every call (~20 us for this kernel's ~30
    arguments, twice that for an adjoint), which dominates a step of one world. Uses Warp internals
    (pinned to 1.19); returns None where they differ, and the caller falls back to ``Launch.launch``.
    """
    import ctypes

    try:
        if not cmd.device.is_cpu or cmd.block_dim != 1:
            return None
        args, adj = wp._src.context._build_cpu_args_structs(cmd.kernel, cmd.hooks, cmd.params, cmd.adjoint)
        bounds = cmd.params[0]
        if cmd.adjoint:
            fn, refs = cmd.hooks.backward, (ctypes.byref(bounds), ctypes.byref(args), ctypes.byref(adj))
        else:
            fn, refs = cmd.hooks.forward, (ctypes.byref(bounds), ctypes.byref(args))
    except (AttributeError, TypeError, ValueError):
        return None

    def call(fn=fn, refs=refs, _keep=(cmd, args, adj, bounds)):  # the structs and module must outlive the call
        fn(*refs)

    return call


def _grad(a):
    if isinstance(a, wp.array):
        return a.grad if a.requires_grad else None
    return None


def _sig(a):
    """Launch-cache key of an argument: arrays by address, shape, strides and gradient address."""
    if isinstance(a, wp.array):
        return (a.ptr, a.shape, a.strides, a.grad.ptr if a.requires_grad and a.grad is not None else None)
    return a
