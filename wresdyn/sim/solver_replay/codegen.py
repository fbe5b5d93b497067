"""Generate the replay kernels for one robot: straight-line Warp code with the robot's geometry folded in.

This module unrolls the recursive algorithms for the robot at hand (:mod:`.dynamics`) and writes them
out as scalar Warp statements (:mod:`.emit`), folding every constant that is 0 or +-1 (axis-aligned
joints, identity joint frames) at generation time. The CPU backend runs one world per thread serially,
so fewer flops per world is directly more env-steps/s. Masses, inertias and all per-DoF parameters are
read from the Newton model arrays of the thread's world, so they are free to differ between worlds and
to carry gradients.

One world step (see :mod:`wresdyn.sim.solver_replay.solver` for the equation):

1. FK, RNEA bias ``c(q, qd)``, CRBA ``M(q)`` (:func:`~.dynamics.dynamics`);
2. drive (PD or servo, chosen per DoF: :func:`~.step_terms.servo_drive`), passive and limit torques, and the
   implicit diagonal;
3. the frictionless velocity ``v* = qd + dt H^-1 rhs`` (:func:`~.dynamics.solve_ltdl`);
4. dry friction: Gauss-Seidel sweeps on ``min_v 1/2 (v - v*)^T (H / dt) (v - v*) + sum_i g_i(v_i)``
   (:func:`~.step_terms.friction_solve`);
5. semi-implicit Euler: ``qd' = v``, ``q' = q + dt qd'``.
"""

from __future__ import annotations

import numpy as np

from ...robot.servo import STICTION_SPEED
from .dynamics import dynamics, inertial_params, solve_ltdl
from .emit import Emitter, branched, gate, indent, outline, unmarked
from .split import split_lanes, split_pieces
from .step_terms import friction_solve, servo_drive
from .tree import ReplayTree

__all__ = ["generate_source"]


_PARAMS = ("ke", "kd", "arm", "fric", "damp", "eff", "lo", "hi", "lke", "lkd")
"""Per-DoF model arrays the kernels read: drive gains, armature, friction, damping, effort, limits."""
_SERVO_PARAMS = ("sdb", "sw0", "su0", "sfs", "sbl", "sof", "sle")
"""Per-DoF arrays the kernels of a robot with servo drives also read: dead band, no-load speed, startup torque,
stiction, backlash, encoder offset, load friction."""
_SCALARS = ("dt", "fric_c", "fric_k", "fric_shift", "kp_implicit")
"""Scalar kernel arguments the step statements read."""


def _load_params(e: Emitter, tree: ReplayTree, friction: bool, servo: np.ndarray | None = None,
                 dofs: list[int] | None = None) -> dict:
    """Loads of the per-DoF arrays; where ``friction``, ``fric_m0`` (one entry per DoF of the whole robot, shared by
    the worlds) and ``fric_on``; the servo arrays only where ``servo``. ``dofs``: where ``tree`` is one branch
    (:func:`_lanes`), its DoFs in the whole robot; ``fric_on`` is then the caller's. ``fric_on``: the world has
    friction, or the kernel argument ``fric_grad[0]`` asks for the friction solve everywhere (an adjoint that
    differentiates a friction of 0: its gradient is not 0)."""
    out = {}
    for name in _PARAMS:
        out[name] = [e.let(f"{name}[bd + {int(tree.qd_offset[k])}]", prefix=f"p{name}_") for k in range(tree.n_dof)]
    for name in _SERVO_PARAMS if servo is not None else ():
        out[name] = [e.let(f"{name}[bd + {int(tree.qd_offset[k])}]", prefix=f"p{name}_") if servo[k] else None
                     for k in range(tree.n_dof)]
    index = list(range(tree.n_dof)) if dofs is None else dofs
    out["m0"] = [e.let(f"fric_m0[{index[k]}]", prefix="pm0_") if friction else None for k in range(tree.n_dof)]
    if friction and dofs is None:
        # != rather than >: a NaN friction runs the solve and shows in the state. The flag is added, not or-ed: with
        # `or` (a branch in the C++) Clang's build of the humanoid's rollout loop kept 3x as many values on the stack
        # and ran 2-3x slower (benchmarks/results/compile/forward_spills.txt)
        # a servo's stiction and load friction need the solve too
        dry = out["fric"] + [x for name in ("sfs", "sle") for x in out.get(name, ()) if x is not None]
        e.lines.append(_friction_flag(dry))
    return out


def _friction_flag(dry: list[str]) -> str:
    """The statement of ``fric_on`` (:func:`_load_params`) from every DoF's dry friction, servo stiction and load
    friction."""
    return f"fric_on = {' + '.join(f'wp.abs({x})' for x in dry)} + S(fric_grad[0]) != S(0.0)"


def _step(e: Emitter, tree: ReplayTree, p: dict, groups: list, q, qd, tq, tqd, jf, g,
          sweeps: int, servo: np.ndarray | None = None) -> tuple[list, list]:
    """Emit one world step; returns the new (q, qd) symbols. DoFs where ``servo`` get the servo law. The friction
    solve runs only where the kernel variable ``fric_on`` holds (:func:`_load_params`; the same result: without
    friction it returns ``v*`` exactly), as a :func:`~.emit.gate` region."""
    n = tree.n_dof
    bias, m_diag, m_off = dynamics(e, tree, groups, q, qd, g)
    rhs, h_diag, drive = [], [], [None] * n
    for k in range(n):
        e.mark(f"dof {k}: drive, passive and limit torques; implicit diagonal")
        ke, kd, arm, _, damp, eff, lo, hi, lke, lkd = (p[name][k] for name in _PARAMS)
        if servo is not None and servo[k]:
            eff = e.let(f"wp.where({eff} > S(0.0), {eff}, S(1.0e30))")
            pd, drive_d, drive_k = servo_drive(e, ke, kd, eff, p["sdb"][k], p["sw0"][k], p["su0"][k], q[k], qd[k],
                                                tq[k], tqd[k], p["sbl"][k], p["sof"][k])
            free, drive[k] = None, pd
        else:
            raw = e.let(f"{ke} * ({tq[k]} - {q[k]}) + {kd} * ({tqd[k]} - {qd[k]})")
            eff = e.let(f"wp.where({eff} > S(0.0), {eff}, S(1.0e30))")  # importers write 0 for "no limit"
            pd = e.let(f"wp.clamp({raw}, -{eff}, {eff})")
            free = e.let(f"wp.where(wp.abs({raw}) < {eff}, S(1.0), S(0.0))")  # saturated: no velocity derivative
        viol = e.let(f"wp.where({q[k]} < {lo}, {lo} - {q[k]}, wp.where({q[k]} > {hi}, {hi} - {q[k]}, S(0.0)))")
        on = e.let(f"wp.where({q[k]} < {lo}, S(1.0), wp.where({q[k]} > {hi}, S(1.0), S(0.0)))")
        if free is None:
            damp_k = e.let(f"{drive_d} + {damp} + {on} * {lkd}")
            stiff_k = e.let(f"kp_implicit * {drive_k} + {on} * {lke}")
        else:
            damp_k = e.let(f"{free} * {kd} + {damp} + {on} * {lkd}")
            stiff_k = e.let(f"kp_implicit * {free} * {ke} + {on} * {lke}")
        rhs.append(e.let(
            f"{pd} + {jf[k]} - {e.sym(bias[k])} - {damp} * {qd[k]} + {lke} * {viol}"
            f" - {on} * {lkd} * {qd[k]} - dt * {stiff_k} * {qd[k]}"
        ))
        h_diag.append(e.let(f"{e.sym(m_diag[k])} + {arm} + dt * {damp_k} + dt * dt * {stiff_k}"))
    qdd = solve_ltdl(e, tree, h_diag, m_off, rhs)
    e.mark("frictionless velocity")
    v = [e.let(f"{qd[k]} + dt * {e.sym(qdd[k])}") for k in range(n)]
    if sweeps > 0:
        v = [e.let(v[k], prefix="v_") for k in range(n)]
        start = len(e.lines)
        mu = list(p["fric"])
        for k in range(n) if servo is not None else ():
            if servo[k]:  # static friction at rest (wresdyn.robot.servo.friction_bound), on the previous velocity,
                # and the gear friction of the load the drive carries this step
                ramp = f"wp.max(S(1.0) - wp.abs({qd[k]}) * S({1.0 / STICTION_SPEED!r}), S(0.0))"
                mu[k] = e.let(f"{mu[k]} + {p['sfs'][k]} * {ramp} + {p['sle'][k]} * wp.abs({drive[k]})")
        vf = friction_solve(e, tree, h_diag, m_off, v, mu, p["m0"], sweeps, qd)
        e.lines[start:] = gate(e.lines[start:] + [f"{v[k]} = {vf[k]}" for k in range(n)], "fric_on")
    e.mark("semi-implicit Euler")
    return [e.let(f"{q[k]} + dt * {v[k]}") for k in range(n)], v


_HEADER = '''"""Generated by wresdyn.sim.solver_replay.codegen for robot tree {digest} ({n} DoF, {scalar}); do not edit."""
import warp as wp

S = wp.{scalar}
V3 = wp.vec3{suffix}
M33 = wp.mat33{suffix}
'''

def _param_args(servo: bool) -> str:
    """The parameter arrays' kernel arguments, in the order of the solver's ``_params``."""
    names = (*_PARAMS, *(_SERVO_PARAMS if servo else ()))
    return (", ".join(f"{name}: wp.array(dtype=S)" for name in names)
            + ", body_mass: wp.array(dtype=S), body_com: wp.array(dtype=V3), body_inertia: wp.array(dtype=M33)")


_GRAVITY = ["g = gravity[w]", "gx = g[0]", "gy = g[1]", "gz = g[2]"]

_FLAT = {"q": "joint_q[bq + {}]", "qd": "joint_qd[bd + {}]", "tq": "target_q[bd + {}]",
         "tqd": "target_qd[bd + {}]", "jf": "joint_f[bd + {}]", "q_out": "joint_q_out[bq + {}]",
         "qd_out": "joint_qd_out[bd + {}]"}
"""Array accesses of the step kernel (Newton's flat per-world layout)."""
_TIME_MAJOR = {"q": "q[t, w, {}]", "qd": "qd[t, w, {}]", "tq": "target_q[t, w, {}]", "tqd": "target_qd[t, w, {}]",
               "jf": "joint_f[t, w, {}]", "q_out": "q[t + 1, w, {}]", "qd_out": "qd[t + 1, w, {}]"}
"""Array accesses of the rollout kernel (time, world, coordinate)."""


def _step_code(tree: ReplayTree, access: dict, sweeps: int, servo: np.ndarray | None = None,
               lane: tuple[int, list[int]] | None = None) -> tuple[list[str], list[str], list[str], list[str]]:
    """Statements of one step: (parameter loads and prologue, state and control loads, compute, stores). ``lane``:
    (its number, its DoFs in the whole robot) where ``tree`` is one branch of :func:`_lanes`: its own names, without
    ``fric_on`` and gravity, which the branches share."""
    n = tree.n_dof
    co = [int(x) for x in tree.q_offset]
    do = [int(x) for x in tree.qd_offset]
    e = Emitter(0 if lane is None else (lane[0] + 1) * 1_000_000)
    p = _load_params(e, tree, sweeps > 0, servo, None if lane is None else lane[1])
    groups = inertial_params(e, tree)
    params, e.lines = unmarked(e.lines) + (_GRAVITY if lane is None else []), []
    q = [e.let(access["q"].format(co[k]), prefix="q_") for k in range(n)]
    qd, tq, tqd, jf = ([e.let(access[kind].format(do[k]), prefix=f"{kind}_") for k in range(n)]
                       for kind in ("qd", "tq", "tqd", "jf"))
    loads, e.lines = e.lines, []
    qn, qdn = _step(e, tree, p, groups, q, qd, tq, tqd, jf, ["gx", "gy", "gz"], sweeps, servo)
    stores = [f"{access['q_out'].format(co[k])} = {qn[k]}" for k in range(n)]
    stores += [f"{access['qd_out'].format(do[k])} = {qdn[k]}" for k in range(n)]
    return params, loads, e.lines, stores


def _lanes(tree: ReplayTree, access: dict, sweeps: int, servo: np.ndarray | None) -> tuple[list[str], list[tuple]]:
    """One step as one thread per branch of the robot (:meth:`~.tree.ReplayTree.branches`): (the statements every
    thread runs first: the world's ``fric_on``, the same flag as the one thread's, and gravity; per branch the
    :func:`_step_code` of the robot restricted to it). A branch's code is the one thread's statements on its DoFs,
    in the same order: on the CPU the results are the same bit for bit; NVRTC compiles the two kernels into code
    that rounds differently (on an H200 the gradient fit's gradients within 2e-7 of the CPU's)."""
    shared = list(_GRAVITY)
    if sweeps > 0:
        do = [int(x) for x in tree.qd_offset]
        dry = [f"fric[bd + {o}]" for o in do] + [f"sfs[bd + {do[k]}]" for k in range(tree.n_dof)
                                                  if servo is not None and servo[k]]
        shared.insert(0, _friction_flag(dry))
    parts = []
    for lane, dofs in enumerate(tree.branches()):
        own = None if servo is None or not servo[dofs].any() else servo[dofs]
        parts.append(_step_code(tree.restrict(dofs), access, sweeps, own, lane=(lane, dofs)))
    return shared, parts


_WARP_GUARD = ["if w >= world_end:", "    return"]


def _under(cond: str, lines: list[str]) -> list[str]:
    return [f"if {cond}:", *("    " + x for x in lines)]


def generate_source(tree: ReplayTree, scalar: str = "float32", backward: bool = True,
                    inline: bool | None = False, friction_sweeps: int = 4, servo: np.ndarray | None = None,
                    pieces: int | None = None, block_dim: int | None = None, smem_spill: bool = False,
                    fast_math: bool = False, lanes: bool = False) -> str:
    """Python source of a module with kernels ``replay_step``, ``replay_rollout`` and ``replay_terms``.

    ``replay_step`` advances one step on Newton's flat ``joint_q``/``joint_qd`` arrays (one thread per
    world). ``replay_rollout`` runs ``n_steps`` steps in one launch (forward only) on time-major
    trajectories (time, world, coordinate), whose row ``t`` is laid out like Newton's ``joint_q``, so its
    adjoint is the step kernel's adjoint launched on rows ``t`` and ``t + 1``. ``replay_terms`` writes
    ``M(q)`` and ``c(q, qd)`` of one world for the parity tests. With ``backward`` the step kernel gets an
    adjoint; its code is cut into functions with the given ``inline`` hint (see :func:`~.emit.outline`).
    ``friction_sweeps`` Gauss-Seidel sweeps solve the dry friction (:func:`~.step_terms.friction_solve`); 0 leaves the
    friction code out; the kernels skip the solve in a world without friction unless ``fric_grad[0]`` is non-zero
    (a run-time branch, so the same module serves any friction values). Every physical parameter is read from the
    arrays: the source depends on the robot's structure and the variant only, never on parameter values. ``servo`` (n_dof,) bool selects the servo law on those DoFs (:func:`~.step_terms.servo_drive`); the
    kernels then also take the servo arrays. ``None`` or none selected: the PD source, unchanged.
    ``pieces`` (with ``backward``): the adjoint comes as a chain of kernels ``replay_piece_<c>`` of about that many
    statements each (:mod:`.split`; listed in ``PIECES``, with ``PIECE_SLOTS`` scratch values per world), and
    ``replay_step`` is the forward kernel alone. ``block_dim``: threads per CUDA block of every kernel (Warp's module
    option, part of the modules' hashes; it bounds the block at launch too), None: Warp's default. ``smem_spill``: let
    NVCC/NVRTC spill registers to shared memory (CUDA 13 toolkits; Warp ignores it elsewhere). ``fast_math``: Warp's
    module option (``--use_fast_math``). ``lanes``: where the robot has several branches from its base, ``replay_step``
    and ``replay_rollout`` (and the adjoint's pieces) run one thread per branch and world (:func:`_lanes`; launched on
    ``(LANES, worlds)``), so a world's serial chain, forward and adjoint, is its longest branch.
    """
    n = tree.n_dof
    servo = None if servo is None or not np.asarray(servo).any() else np.asarray(servo, dtype=bool)
    param_args = _param_args(servo is not None)
    src = [_HEADER.format(digest=tree.digest(), n=n, scalar=scalar, suffix="d" if scalar == "float64" else "f")]
    module = ({"block_dim": int(block_dim)} if block_dim else {}) | ({"fast_math": True} if fast_math else {})
    options = {"module": "unique", "module_options": module or None}
    if smem_spill:  # the spill space is sized for the largest block the kernel declares it may run in
        options |= {"enable_cuda_smem_spilling": True, "launch_bounds": int(block_dim or 256)}
    src.append(f"KERNEL = {options!r}\nBLOCK_DIM = {block_dim and int(block_dim)!r}\n")  # None: Warp's default
    n_lanes = len(tree.branches()) if lanes else 1
    if n_lanes > 1:  # launched on (LANES, worlds); without it on (worlds,)
        src.append(f"LANES = {n_lanes}\n")

    if n_lanes > 1:
        shared, parts = _lanes(tree, _FLAT, friction_sweeps, servo)
    else:
        params, loads, compute, stores = _step_code(tree, _FLAT, friction_sweeps, servo)
    step_args = ("world_start: int, dt: S, fric_c: S, fric_k: S, fric_shift: S, kp_implicit: S, "
                 "fric_m0: wp.array(dtype=S),\n") + f"""    fric_grad: wp.array(dtype=wp.int32),
    {param_args}, gravity: wp.array(dtype=V3),
    joint_q: wp.array(dtype=S), joint_qd: wp.array(dtype=S), target_q: wp.array(dtype=S),
    target_qd: wp.array(dtype=S), joint_f: wp.array(dtype=S),
    joint_q_out: wp.array(dtype=S), joint_qd_out: wp.array(dtype=S),"""
    prelude = ["w = wp.tid() + world_start", f"bq = w * {tree.coords_per_world}", f"bd = w * {tree.dofs_per_world}",
               f"bb = w * {tree.bodies_per_world}"]
    # laned: launched on (LANES, worlds rounded up to a warp) so that a warp runs one branch's code (a warp holding
    # several branches would run them one after another); the threads past the chunk's last world return
    laned = ["lane, i = wp.tid()", "w = i + world_start", *_WARP_GUARD, *prelude[1:]]
    if n_lanes > 1:
        step_args = step_args.replace("world_start: int,", "world_start: int, world_end: int,", 1)
    if backward and pieces:
        if n_lanes > 1:
            bodies, slots = split_lanes(parts, max(1, pieces // n_lanes))  # a kernel holds a piece of each lane
            bodies = [laned + shared + b for b in bodies]
        else:
            bodies, slots = split_pieces(params + loads, compute, stores, pieces)
            bodies = [prelude + b for b in bodies]
        for c, body in enumerate(bodies):
            src.append(f'''
@wp.kernel(enable_backward=True, **KERNEL)
def replay_piece_{c}(
    {step_args} scratch: wp.array2d(dtype=S),
):
{indent(body, 1)}
''')
        src.append(f"PIECES = [{', '.join(f'replay_piece_{c}' for c in range(len(bodies)))}]\nPIECE_SLOTS = {slots}\n")
        backward = False  # replay_step: the forward kernel alone
    if n_lanes > 1:
        body = [*laned, *shared]
        for lane, (params, loads, compute, stores) in enumerate(parts):
            if backward:
                external = {x.split(" = ", 1)[0] for x in params + loads + shared} | set(_SCALARS)
                funcs, compute = outline(compute, f"step_part_l{lane}_", inline, stores, external)
                src += funcs
            body += _under(f"lane == {lane}", params + loads + branched(compute) + stores)
    else:
        if backward:
            external = {x.split(" = ", 1)[0] for x in params + loads} | set(_SCALARS)
            funcs, compute = outline(compute, "step_part", inline, stores, external)
            src += funcs
        body = prelude + params + loads + branched(compute) + stores
    src.append(f'''
@wp.kernel(enable_backward={backward}, **KERNEL)
def replay_step(
    {step_args}
):
{indent(body, 1)}
''')

    if n_lanes > 1:
        shared, parts = _lanes(tree, _TIME_MAJOR, friction_sweeps, servo)
        head, body = ["lane, i = wp.tid()", "w = i + world_start", *_WARP_GUARD], list(shared)
        for lane, (params, loads, compute, stores) in enumerate(parts):
            body += _under(f"lane == {lane}", [*params, "for t in range(n_steps):",
                                                *("    " + x for x in loads + branched(compute) + stores)])
    else:
        params, loads, compute, stores = _step_code(tree, _TIME_MAJOR, friction_sweeps, servo)
        head, body = ["w = wp.tid() + world_start"], [*params, "for t in range(n_steps):",
                                                      *("    " + x for x in loads + branched(compute) + stores)]
    end = "world_end: int, " if n_lanes > 1 else ""
    src.append(f'''
@wp.kernel(enable_backward=False, **KERNEL)
def replay_rollout(
    world_start: int, {end}n_steps: int, dt: S, fric_c: S, fric_k: S, fric_shift: S, kp_implicit: S,
    fric_m0: wp.array(dtype=S), fric_grad: wp.array(dtype=wp.int32), {param_args},
    gravity: wp.array(dtype=V3), target_q: wp.array3d(dtype=S), target_qd: wp.array3d(dtype=S),
    joint_f: wp.array3d(dtype=S),
    q: wp.array3d(dtype=S), qd: wp.array3d(dtype=S),
):
{indent(head + [f"bd = w * {tree.dofs_per_world}", f"bb = w * {tree.bodies_per_world}"] + body, 1)}
''')

    e = Emitter()
    groups = inertial_params(e, tree)
    e.lines += _GRAVITY
    q = [e.let(f"q[w, {k}]", prefix="q_") for k in range(n)]
    qd = [e.let(f"qd[w, {k}]", prefix="qd_") for k in range(n)]
    bias, m_diag, m_off = dynamics(e, tree, groups, q, qd, ["gx", "gy", "gz"])
    for k in range(n):
        e.lines.append(f"bias[w, {k}] = {e.sym(bias[k])}")
        e.lines.append(f"mass_matrix[w, {k}, {k}] = {e.sym(m_diag[k])}")
    for (k, j), v in m_off.items():
        e.lines.append(f"mass_matrix[w, {k}, {j}] = {e.sym(v)}")
        e.lines.append(f"mass_matrix[w, {j}, {k}] = {e.sym(v)}")
    src.append(f'''
@wp.kernel(enable_backward=False, **KERNEL)
def replay_terms(
    world: int, body_mass: wp.array(dtype=S), body_com: wp.array(dtype=V3), body_inertia: wp.array(dtype=M33),
    gravity: wp.array(dtype=V3), q: wp.array2d(dtype=S), qd: wp.array2d(dtype=S),
    mass_matrix: wp.array3d(dtype=S), bias: wp.array2d(dtype=S),
):
    w = wp.tid()
    bb = world * {tree.bodies_per_world}
{indent(unmarked(e.lines), 1)}
''')
    return "\n".join(src)
