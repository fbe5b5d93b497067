"""``SolverReplay``: a Newton solver specialised for PD replay of fixed-base robots.

The replay workload is one articulated robot per world, PD drives plus a residual torque, no contacts.
Newton's ``SolverFeatherstone`` handles it with ~20 kernel launches per step, a dense ``J^T M J`` mass
matrix and explicit PD (unstable at 500 Hz on light joints without armature). This solver runs a step in one
kernel, one thread per world (on CUDA per world and branch of the base), with code generated for the robot at hand
(:mod:`.codegen`): RNEA bias, CRBA mass matrix, a tree ``L^T D L`` factorisation, a dry-friction solve and
semi-implicit Euler, all differentiable by Warp's Tape. One step, with ``H`` the matrix the kernel factorises::

    H = M(q) + A + dt D + dt^2 K
    H (v* - qd) = dt (tau_pd + joint_f - c(q, qd) - d qd + tau_lim - dt K qd)        frictionless velocity
    v = argmin_v 1/2 (v - v*)^T (H / dt) (v - v*) + sum_i g_i(v_i)                   dry friction
    qd' = v,   q' = q + dt qd'

- ``M(q)``, ``c(q, qd)``: from the link masses, centres of mass and inertias read every launch from
  ``Model.body_mass/body_com/body_inertia`` of each world (bodies welded by fixed joints are composed
  into their moving body in generated code), so they may differ between worlds and change without
  recompiling.
- ``A``: armature (``Model.joint_armature``) on the diagonal.
- ``tau_pd = clamp(ke (q* - q) + kd (qd* - qd), -effort, effort)``, the position actuator of eq. (1)
  of the paper (``Model.joint_target_ke/kd``, ``joint_effort_limit`` with 0 meaning unlimited,
  ``Control.joint_target_q/qd``).
- On a DoF whose drive is a smart servo (``Model.joint_servo`` 1, set by
  :func:`wresdyn.robot.servo.attach_servo`; chosen when the kernels are generated, so PD DoFs compile to the
  same code as without servos), ``tau_pd`` is the servo law instead, in SI units::

      e_b = e - clamp(e, -b, b),  e = q* - q                        dead band b [rad] (soft threshold)
      u   = clamp(ke e_b + u0 clamp(e_b / r, -1, 1)                duty in torque units [N m], U = effort,
                  + kd (qd* - qd), -U, U)                         u0 startup torque, ramp r one tick
      tau = clamp(u - (U / w0) qd, -U, U)                           DC motor line, no-load speed w0 [rad/s]

  (``b = Model.joint_servo_deadband``, ``u0 = Model.joint_servo_startup_torque``, ``w0 =
  Model.joint_servo_noload_speed``, 0: no line; the backlash ``joint_servo_backlash`` and the encoder offset
  ``joint_servo_encoder_offset`` enter as :mod:`wresdyn.robot.servo` states; ``q*`` is the goal
  after the servo's acceleration profile, which the command path applies: :mod:`wresdyn.sim.bank`).
- ``D``: velocity derivatives treated implicitly, as MuJoCo's ``implicitfast`` integrator does:
  drive ``kd`` while the drive is not saturated (a clamped force has no velocity derivative; a servo's
  ``kd + U / w0`` while neither its duty nor its torque is clamped), passive damping ``d`` (``Model.joint_damping``)
  and the limit damping.
- ``K``: position derivatives treated implicitly: the joint-limit stiffness always, the drive ``ke``
  only with ``implicit_stiffness=True`` (off by default to match ``implicitfast``; a servo's only outside its
  dead band).
- ``tau_lim``: penalty ``limit_ke * violation - limit_kd * qd`` outside ``[lower, upper]``
  (``Model.joint_limit_*``); unlike Newton's semi-implicit convention the drive stays on at a limit.
- ``joint_f``: the residual torque ``tau_res`` of eq. (1), added unclamped.
- ``g_i``: dry friction of ``mu_i = Model.joint_friction``, by default MuJoCo's soft ``frictionloss``
  constraint written per DoF: friction torque ``-clamp((a_i + b qd_i) / R_i, -mu_i, mu_i)`` with ``a_i`` the
  step's acceleration ``(v_i - qd_i) / dt``, ``b = 2 / (dmax timeconst)`` and ``1 / R_i = d0 / (1 - d0) m0_i``,
  ``m0_i`` the DoF's effective inertia ``1 / (M^-1)_ii`` at the reference pose of the model as built (MuJoCo's
  ``1 / dof_invweight0``; default ``solref``/``solimp``: ``d0 = 0.9``, ``dmax = 0.95``, ``timeconst = 0.02``).
  Below ``mu_i`` the joint creeps (a virtual inertia ``1 / R_i`` and damper ``b / R_i``), above it slides
  against ``mu_i``. On a servo DoF the bound is ``mu_i + s_i max(1 - |qd_i| / v_s, 0)`` with the stiction ``s_i =
  Model.joint_servo_stiction`` (:func:`wresdyn.robot.servo.friction_bound`): a static friction while the joint rests,
  falling to ``mu_i`` once it moves (``qd`` the velocity before the step), plus ``eta_i |tau_i|``, the gear friction of
  the step's drive torque (``eta_i = Model.joint_servo_load_friction``). The problem is solved by ``friction_sweeps``
  symmetric Gauss-Seidel sweeps, each coordinate in closed form (:mod:`.codegen`). ``friction_kappa`` selects the damper
  law instead, a saturated damper ``-clamp(kappa H_ii v_i, -mu_i, mu_i)`` on the new velocity (``kappa = inf``: hard
  Coulomb friction, exact sticking).

Why the soft law is the default: against MuJoCo C (``frictionloss``, default ``solref``/``solimp``,
``implicitfast``, dt = 2 ms) it creeps and slides as MuJoCo does to float32 round-off on one hinge, and the
"real" robot of the shipped data replayed with its true parameters matches its noise-free recording to 0.0003 rad,
where the damper law leaves 0.0063 rad, the whole gap between the two simulators. The figures are in
docs/results/simulation.md ("Dry friction against MuJoCo") and
``benchmarks/results/grey_box/soft_friction/friction_law.txt``, made by ``benchmarks/fidelity/friction_law.py``.

Gradients (a ``wp.Tape`` around :meth:`step` or :meth:`rollout`, ``requires_grad``) reach the states,
targets and ``joint_f`` and, when the model was finalized with ``requires_grad``, every parameter above:
the per-DoF drive and joint arrays and ``body_mass/body_com/body_inertia`` (of the symmetrised inertia:
``I_ij`` and ``I_ji`` get half each). A stuck joint's velocity does not depend on its ``mu`` (gradient 0).

The generated code depends on the robot's structure (topology, joint frames and axes, which DoFs have servo
drives), the friction solver settings and the variant (forward, or with an adjoint) only, never on a parameter's
value: any masses, inertias, gains or friction, identified ones included, run on the module the robot file's
values compiled. The kernels skip the friction solve in a world whose friction is 0 everywhere (its result there
is ``v*`` exactly), the adjoint too unless :attr:`SolverReplay.friction_grad` asks for the gradient to a friction of
0, which is not 0 (a sliding joint's ``-mu sign(v)``).

Not supported: floating bases, contacts, mimic joints, ``joint_target_mode`` (drives act wherever
``ke`` or ``kd`` is non-zero), velocity limits. ``State.body_q`` is only refreshed with
``update_body_q=True``.
"""

from __future__ import annotations

import numpy as np
import warp as wp
from newton import ModelFlags
from newton.solvers import SolverBase

from .kernels import ADJOINT_PIECES, choose_pieces, compile_now, deferring, load_kernels
from .launch import LaunchPlans, launch_signature
from .tree import ReplayTree, tree_from_model

__all__ = ["ADJOINT_PIECES", "FRICTION_KAPPA", "FRICTION_SWEEPS", "SolverReplay"]

_MJ_D0, _MJ_DMAX, _MJ_TIMECONST = 0.9, 0.95, 0.02
"""MuJoCo's default ``solimp[0]``, ``solimp[1]`` and ``solref[0]`` [s]."""
FRICTION_KAPPA = _MJ_D0 / (1.0 - _MJ_D0) * 2.0 / (_MJ_DMAX * _MJ_TIMECONST)
"""Rate of the damper friction law's ``d_i = kappa H_ii`` [1/s], 947 (``SolverReplay(friction_kappa=)``):
the creep velocity of MuJoCo's default soft ``frictionloss`` on a lone joint (module docstring)."""
FRICTION_SWEEPS = 8
"""Default Gauss-Seidel sweeps of the friction solve: on the humanoid 0.0116 rad max against MuJoCo (16 sweeps
0.0027, 4 sweeps 0.040; ``benchmarks/results/grey_box/soft_friction/friction_law.txt``)."""

_JOINT_PARAMS = ("joint_target_ke", "joint_target_kd", "joint_armature", "joint_friction", "joint_damping",
                 "joint_effort_limit", "joint_limit_lower", "joint_limit_upper", "joint_limit_ke", "joint_limit_kd")
"""Per-DoF model arrays the kernels read, in the order of their arguments."""
_SERVO_PARAMS = ("joint_servo_deadband", "joint_servo_noload_speed", "joint_servo_startup_torque",
                 "joint_servo_stiction", "joint_servo_backlash", "joint_servo_encoder_offset",
                 "joint_servo_load_friction")
"""Per-DoF model arrays the kernels of a model with servo drives also read."""
_BODY_PARAMS = ("body_mass", "body_com", "body_inertia")
"""Per-body model arrays the kernels read."""


class SolverReplay(LaunchPlans, SolverBase):
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

    def __init__(self, model, *, friction_kappa: float | None = None, friction_sweeps: int = FRICTION_SWEEPS,
                 implicit_stiffness: bool = False, requires_grad: bool | None = None,
                 friction_grad: bool | None = None, update_body_q: bool = False, threads: int = 1, dtype=wp.float32,
                 adjoint_pieces: int | None = None):
        """
        Args:
            model: Newton model holding one fixed-base robot per world (same topology and joint frames;
                inertias and joint parameters may differ).
            friction_kappa: ``None`` (default): dry friction as MuJoCo's soft ``frictionloss`` constraint with
                the default ``solref``/``solimp`` (module docstring). A number: the damper law, a saturated damper
                on the new velocity ``d_i = kappa H_ii`` [1/s] (:data:`FRICTION_KAPPA` matches MuJoCo's creep
                rate only); ``math.inf`` gives hard Coulomb friction with exact sticking, 0 no friction.
            friction_sweeps: Gauss-Seidel sweeps of the friction solve; 0 leaves friction out of the
                kernels (``joint_friction`` is then ignored).
            implicit_stiffness: Also treat the drive stiffness implicitly (``dt^2 ke`` on the diagonal);
                more stable for very stiff drives, but no longer MuJoCo ``implicitfast`` parity.
            requires_grad: Compile adjoint kernels (default: ``model.requires_grad``). The adjoint reaches the
                parameter arrays whenever the model's arrays carry gradients (``model.requires_grad``).
            friction_grad: Initial :attr:`friction_grad` (default: whether ``joint_friction`` carries gradients).
            update_body_q: Refresh ``state_out.body_q/body_qd`` with ``newton.eval_fk`` after each step.
            threads: CPU only: split the worlds over this many host threads (Warp runs a CPU kernel's
                threads one after another; separate launches run concurrently).
            dtype: ``wp.float32`` (Newton's state arrays) or ``wp.float64`` (:meth:`rollout` only, for
                finite-difference checks; the parameters are then float64 copies, see :attr:`parameters`).
            adjoint_pieces: With ``requires_grad``: the adjoint as a chain of kernels of about this many statements
                (:mod:`.split`), 0 as one kernel. Default: :func:`.kernels.choose_pieces` (on CUDA the one kernel
                once Warp's cache holds it, pieces of :data:`ADJOINT_PIECES` until then; on the CPU one kernel).
        """
        super().__init__(model)
        if dtype not in (wp.float32, wp.float64):
            raise ValueError("dtype must be wp.float32 or wp.float64")
        if (friction_kappa is not None and not friction_kappa >= 0.0) or int(friction_sweeps) < 0:
            raise ValueError("friction_kappa must be >= 0 (inf: hard Coulomb) and friction_sweeps >= 0")
        self.friction_kappa = None if friction_kappa is None else float(friction_kappa)
        self.friction_sweeps = int(friction_sweeps)
        self.implicit_stiffness = bool(implicit_stiffness)
        self.requires_grad = bool(model.requires_grad if requires_grad is None else requires_grad)
        self.update_body_q = bool(update_body_q)
        self.threads = max(1, int(threads)) if model.device.is_cpu else 1
        self.dtype = dtype
        if adjoint_pieces is not None and int(adjoint_pieces) < 0:
            raise ValueError("adjoint_pieces must be >= 0")
        self._pieces_arg = adjoint_pieces
        self.adjoint_pieces = 0  # statements per adjoint kernel in use (0: one kernel), set by _load
        self._scratch = None
        self.parameters: dict[str, wp.array] = {}
        """The arrays the kernels read, by :class:`newton.Model` attribute name (``joint_*`` per DoF,
        ``body_mass/com/inertia`` per body, ``gravity``): the model's own arrays for float32, float64 copies
        for float64 (made again by :meth:`notify_model_changed`), whose ``.grad`` then holds the parameter
        gradients."""
        self._pool = None
        self._plans: dict = {}
        self._zeros: dict = {}
        self._control0 = None
        self._fric_grad = wp.zeros(1, dtype=wp.int32, device=model.device)
        self._fric_grad_on = False
        self._build()
        if friction_grad is None:
            friction_grad = self.requires_grad and self.parameters["joint_friction"].requires_grad
        self.friction_grad = friction_grad

    @property
    def friction_grad(self) -> bool:
        """Run the friction solve also in worlds whose friction is 0 everywhere, so that the adjoint gives the
        gradient to ``joint_friction`` there (without it, that gradient is 0 and every other one the same: the
        solve returns ``v*`` exactly where there is no friction). Off, a frictionless robot's steps and their
        adjoints skip the solve; a kernel argument array, so a change reaches recorded launches and CUDA graphs."""
        return self._fric_grad_on

    @friction_grad.setter
    def friction_grad(self, on: bool) -> None:
        if bool(on) != self._fric_grad_on:
            self._fric_grad.fill_(1 if on else 0)
            self._fric_grad_on = bool(on)

    # ------------------------------------------------------------------ set-up
    def _build(self) -> None:
        self.tree: ReplayTree = tree_from_model(self.model)
        self.servo = self._servo_dofs()
        self._load()
        body = [self.parameters[n][:self.tree.bodies_per_world] for n in _BODY_PARAMS]
        if deferring():  # fric_m0 at the first launch (after the caller's batch compile), of the values as built
            body = [wp.clone(b) for b in body]
        self._m0, self._m0_from = None, (body, self.model.joint_armature.numpy()[np.asarray(self.tree.qd_offset)])
        if not deferring():
            self._reference_inertia()

    def _reference_inertia(self) -> wp.array:
        """``fric_m0``: each DoF's effective inertia at the reference pose (all joints at 0) of world 0 as built,
        armature included, ``1 / (M^-1)_ii`` [kg m^2 or kg], shape (n_dof,): MuJoCo's ``1 / dof_invweight0``,
        the scale of its soft friction's regulariser. Fixed at construction (as MuJoCo fixes it when it compiles
        a model): edits of masses or armature later, identification's included, do not change it."""
        if self._m0 is not None:
            return self._m0
        n = self.tree.n_dof
        body, arm = self._m0_from
        mass, _ = self._terms(np.zeros(n), np.zeros(n), 0, body)
        inv = np.linalg.inv(mass[0].astype(np.float64) + np.diag(arm.astype(np.float64)))
        dt = np.float64 if self.dtype == wp.float64 else np.float32
        self._m0 = wp.array((1.0 / np.diag(inv)).astype(dt), dtype=self.dtype, device=self.model.device)
        return self._m0

    def _servo_dofs(self) -> np.ndarray | None:
        """Which DoFs of a world (in DoF order) have a servo drive (``Model.joint_servo``), or None for none."""
        flags = getattr(self.model, "joint_servo", None)
        if flags is None:
            return None
        tr = self.tree
        per_world = flags.numpy().reshape(tr.world_count, tr.dofs_per_world)[:, tr.qd_offset] != 0
        if not (per_world == per_world[:1]).all():
            raise ValueError("SolverReplay: every world needs the same servo joints (Model.joint_servo)")
        return per_world[0] if per_world[0].any() else None

    def _load(self) -> None:
        scalar = "float64" if self.dtype == wp.float64 else "float32"
        sweeps = self.friction_sweeps if self.friction_kappa != 0.0 else 0  # kappa = 0: no friction at all
        dev = self.model.device
        self.adjoint_pieces, later = choose_pieces(self.tree, scalar, self.requires_grad, dev, sweeps, self.servo,
                                                   self._pieces_arg)
        self.kernels = load_kernels(self.tree, scalar, self.requires_grad, dev.is_cuda, sweeps, self.servo,
                                    self.adjoint_pieces)
        compile_now(self.kernels, dev, later)
        self._scratch = None
        if self.adjoint_pieces:  # the values the chain's kernels hand on, (slots, worlds): one step at a time
            self._scratch = wp.zeros((max(1, self.kernels.PIECE_SLOTS), self.tree.world_count), dtype=self.dtype,
                                     device=self.model.device, requires_grad=True)
        self._refresh_params()

    def _refresh_params(self) -> None:
        self._plans.clear()  # recorded launches hold the parameter arrays
        m = self.model
        joint = (*_JOINT_PARAMS, *(_SERVO_PARAMS if self.servo is not None else ()))
        names = (*joint, *_BODY_PARAMS, "gravity")
        if self.dtype == wp.float32:
            self.parameters = {n: getattr(m, n) for n in names}
        else:
            wide = {wp.float32: wp.float64, wp.vec3f: wp.vec3d, wp.mat33f: wp.mat33d}
            self.parameters = {
                n: wp.array(getattr(m, n).numpy().astype(np.float64), dtype=wide[getattr(m, n).dtype], device=m.device,
                            requires_grad=self.requires_grad and n != "gravity")
                for n in names
            }
        self._params = [self.parameters[n] for n in (*joint, *_BODY_PARAMS)]
        self._gravity = self.parameters["gravity"]

    def notify_model_changed(self, flags: int) -> None:
        """Regenerate after joint-frame edits (``JOINT_PROPERTIES``); masses, inertias, gains, limits, armature,
        friction and gravity are read live (float32) or re-copied here (float64), never recompiled."""
        if int(flags) & int(ModelFlags.JOINT_PROPERTIES):
            self._build()
        else:
            self._refresh_params()

    # ------------------------------------------------------------------ launching
    def _leading_args(self, dt: float) -> list:
        """The kernels' first arguments: ``dt``, the friction law's ``fric_c``, ``fric_k``, ``fric_shift``
        (:func:`.step_terms.friction_solve`), ``kp_implicit`` and the arrays ``fric_m0`` and ``fric_grad``."""
        k = self.friction_kappa
        if k is None:  # MuJoCo's soft frictionloss: c_i = d0 / (1 - d0) m0_i / H_ii, shift = 1 - b dt
            c, kdt, shift = _MJ_D0 / (1.0 - _MJ_D0), 0.0, 1.0 - 2.0 / (_MJ_DMAX * _MJ_TIMECONST) * dt
        else:  # a damper kappa H_ii on the new velocity (inf: hard Coulomb)
            c, kdt, shift = 0.0, k * dt, 0.0
        return [float(dt), c, kdt, shift, 1.0 if self.implicit_stiffness else 0.0, self._reference_inertia(),
                self._fric_grad]

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
        key = ("step", float(dt), *map(launch_signature, arrays))
        args, outputs = [*self._leading_args(dt), *self._params, self._gravity, *arrays[:5]], arrays[5:]
        kernel = self.kernels.replay_step
        self._execute(self._plan(key, lambda c: [self._command(kernel, c, args, outputs)]))
        self._record(lambda: self._execute(self._plan(key + ("adjoint",), lambda c: self._adjoint(c, args, outputs))),
                     args + outputs)
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
        ``target_qd.grad``, ``joint_f.grad`` and the ``.grad`` of the parameter arrays in
        :attr:`parameters` (the model's own for float32, when it was finalized with ``requires_grad``).
        """
        t_len, w = target_q.shape[0], target_q.shape[1]
        tr = self.tree
        if (w != tr.world_count or q.shape != (t_len + 1, w, tr.coords_per_world)
                or qd.shape != (t_len + 1, w, tr.dofs_per_world) or target_q.shape[2] != tr.dofs_per_world):
            raise ValueError(f"rollout shapes: q {q.shape}, qd {qd.shape}, target_q {target_q.shape} do not match "
                             f"(T+1 | T, {tr.world_count} worlds, {tr.coords_per_world} coords / "
                             f"{tr.dofs_per_world} dofs)")
        if target_qd is None or joint_f is None:
            if target_q.shape not in self._zeros:
                self._zeros[target_q.shape] = wp.zeros(target_q.shape, dtype=self.dtype, device=self.model.device)
            zeros = self._zeros[target_q.shape]
            target_qd = zeros if target_qd is None else target_qd
            joint_f = zeros if joint_f is None else joint_f
        arrays = [q, qd, target_q, target_qd, joint_f]
        key = ("rollout", float(dt), *map(launch_signature, arrays))
        fixed = [*self._leading_args(dt), *self._params, self._gravity]
        kernel = self.kernels.replay_rollout
        self._execute(self._plan(key, lambda c: [self._command(kernel, c, [t_len, *fixed, *arrays[2:]], arrays[:2])]))
        if wp._src.context.runtime.tape is None:
            return

        def adjoints(chunk):
            # step t's adjoint reads the gradient of state t + 1 and adds into state t and step t's inputs;
            # row t of a time-major trajectory has Newton's flat layout, so the step kernel's adjoint applies
            rows = [[a[t].flatten() for t in range(a.shape[0])] for a in arrays]
            return [call for t in reversed(range(t_len))
                    for call in self._adjoint(chunk, [*fixed, *(r[t] for r in rows)], [rows[0][t + 1], rows[1][t + 1]])]

        self._record(lambda: self._execute(self._plan(key + ("adjoint",), adjoints)), fixed + arrays)

    def dynamics_terms(self, q: np.ndarray, qd: np.ndarray, world: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """Mass matrix ``M(q)`` (without armature) and bias ``c(q, qd)`` (Coriolis, centrifugal, gravity) of
        ``world``'s robot (its body parameters, world 0's gravity) at a batch of states, in DoF order; for
        tests. Shapes (B, n, n) and (B, n)."""
        return self._terms(q, qd, world, [self.parameters[name] for name in _BODY_PARAMS])

    def _terms(self, q, qd, world: int, body: list) -> tuple[np.ndarray, np.ndarray]:
        q, qd = np.atleast_2d(q), np.atleast_2d(qd)
        b, n = q.shape[0], self.tree.n_dof
        dev = self.model.device
        dt = np.float64 if self.dtype == wp.float64 else np.float32
        m_out = wp.zeros((b, n, n), dtype=self.dtype, device=dev)
        c_out = wp.zeros((b, n), dtype=self.dtype, device=dev)
        g = wp.array(np.repeat(self._gravity.numpy()[:1], b, axis=0), dtype=self._gravity.dtype, device=dev)
        q_in = wp.array(q.astype(dt), dtype=self.dtype, device=dev)
        qd_in = wp.array(qd.astype(dt), dtype=self.dtype, device=dev)
        wp.launch(self.kernels.replay_terms, dim=b, inputs=[int(world), *body, g, q_in, qd_in],
                  outputs=[m_out, c_out], device=dev, block_dim=self.kernels.BLOCK_DIM)
        return m_out.numpy(), c_out.numpy()

