"""Two terms of the replay step as straight-line Warp code (:mod:`.codegen` emits the rest): the dry-friction solve
of one step (:func:`friction_solve`, Gauss-Seidel sweeps on the velocity problem) and the servo drive law of one DoF
(:func:`servo_drive`, :mod:`wresdyn.robot.servo`)."""

from __future__ import annotations

import itertools

from ...robot.servo import STARTUP_RAMP
from .emit import Emitter
from .tree import ReplayTree

__all__ = ["friction_solve", "servo_drive"]


def friction_solve(e: Emitter, tree: ReplayTree, h_diag: list, h_off: dict, v_star: list, mu: list, m0: list,
                   sweeps: int, qd: list) -> list:
    """Dry friction as the velocity problem of one step, solved by ``sweeps`` Gauss-Seidel sweeps.

    With the frictionless velocity ``v*`` (``H (v* - qd) = dt rhs``), friction torques ``tau_f`` change the
    step to ``H (v - v*) = dt tau_f``, ``-tau_f in dg(v)``: the optimality condition of

        min_v 1/2 (v - v*)^T (H / dt) (v - v*) + sum_i g_i(v_i).

    ``g_i`` is a saturated damper on ``w_i = v_i - sigma qd_i`` (``qd`` the velocity before the step),
    ``tau_i = -clamp(c_i H_ii w_i / dt, -mu_i, mu_i)`` with ``c_i = fric_c m0_i / H_ii + fric_k``
    (``fric_*`` kernel arguments, ``m0`` the array ``fric_m0``): MuJoCo's soft ``frictionloss`` has
    ``fric_c = d0 / (1 - d0)``, ``m0_i`` the DoF's effective inertia at the reference pose (MuJoCo's
    ``1 / dof_invweight0``), ``fric_k = 0``, ``sigma = 1 - b dt`` (:mod:`.solver`); the plain damper on the new
    velocity has ``fric_c = 0``, ``fric_k = kappa dt``, ``sigma = 0`` (Coulomb ``mu_i |v_i|`` for ``kappa = inf``).
    Minimising over ``v_i`` alone, the others fixed, is in closed form: with the unconstrained
    ``u = v*_i - sum_{j != i} (H_ij / H_ii) (v_j - v*_j)``,

        v_i = u - clamp(beta_i (u - sigma qd_i), -mu_i dt / H_ii, mu_i dt / H_ii),   beta_i = 1 - 1 / (1 + c_i)

    (``beta = 1``: a soft threshold that returns exactly 0 when the joint sticks; below the threshold the
    implicit damper), written ``u - beta clamp(w, -t / beta, t / beta)`` so that the stuck case stays exact. ``H`` couples a
    DoF only with its ancestors and descendants, so a sweep costs one multiply-add per such pair. Each
    sweep visits the DoFs by depth (root to leaves, then back: symmetric Gauss-Seidel), which is the DoF
    order up to swaps of DoFs of different branches, which do not couple (the same result). A DoF without
    friction (``mu_i = 0``) still moves, as it answers the friction torques of the DoFs it is coupled to: its
    bound is 0, so ``v_i = u`` exactly, and a world without friction gets ``v = v*`` exactly.
    """
    n = tree.n_dof
    depth = [len(tree.ancestors(k)) for k in range(n)]
    order = sorted(range(n), key=lambda k: (depth[k], k))
    coupled: list[list[tuple[int, object]]] = [[] for _ in range(n)]
    inv_h = [e.let(f"S(1.0) / {e.sym(h_diag[k])}") for k in range(n)]
    for (k, j), h in h_off.items():
        coupled[k].append((j, e.sp((h, inv_h[k]))))
        coupled[j].append((k, e.sp((h, inv_h[j]))))
    # clamp(beta w, -t, t) = beta clamp(w, -t / beta, t / beta), t = mu dt / H_ii
    beta = [e.let(f"S(1.0) - S(1.0) / (S(1.0) + fric_c * {m0[k]} * {inv_h[k]} + fric_k)") for k in range(n)]
    bound = [e.let(f"dt / {beta[k]} * {mu[k]} * {inv_h[k]}") for k in range(n)]
    last: dict[int, tuple] = {}  # each DoF's latest (u, clamp); v is made from it at the end
    delta: dict[int, object] = {}  # v_j - v*_j of the DoFs visited so far
    stamp: dict[int, int] = {}  # when each delta was made: the newest is summed last, the rest need not wait
    clock = itertools.count()
    for s in range(sweeps):
        e.mark(f"friction sweep {s}")
        for i in (order if s % 2 == 0 else order[::-1]):
            terms = sorted((stamp[j], h, delta[j]) for j, h in coupled[i] if j in delta)
            coupling = e.sp(*[(h, d) for _, h, d in terms])
            u = e.sym(e.sp((v_star[i],), (-1.0, coupling)))
            # clamp(w, -b, b) as two selects: with wp.clamp (NaN-aware fmin/fmax) one sweep cost 20 % of
            # the humanoid's fused step, with selects 4 %
            b = bound[i]
            w = e.let(f"{u} - fric_shift * {qd[i]}")
            c = e.let(f"wp.where({w} > {b}, {b}, wp.where({w} < -{b}, -{b}, {w}))")
            delta[i] = e.sp((-1.0, coupling), (-1.0, beta[i], c))
            last[i] = (u, c)
            stamp[i] = next(clock)
    e.mark("friction result")
    # u - beta c, not v* + delta: exactly 0 when the joint sticks with beta = 1
    return [e.let(f"{u} - {beta[i]} * {c}") for i, (u, c) in sorted(last.items())]


def servo_drive(e: Emitter, ke, kd, eff, db, w0, u0, q, qd, tq, tqd, bl, off) -> tuple[str, str, str]:
    """The servo law of :mod:`wresdyn.robot.servo` for one DoF: (torque, its velocity derivative's magnitude
    ``d``, its position derivative's magnitude ``k``), ``d``/``k`` 0 where a clamp is saturated (and ``k`` inside
    the dead band)::

        e = q* - (q + o),  e_m = e - clamp(e, -beta, beta),  e_b = e_m - clamp(e_m, -b, b),
        u = clamp(ke e_b + u0 clamp(e_b / r, -1, 1) + kd (qd* - qd), -U, U),
        tau = g clamp(u - (U / w0) qd, -U, U),  g = min(|e_m| / r, 1) if beta > 0 else 1

    ``U`` the effort limit (here finite), ``w0 = 0``: no torque-speed line, ``u0`` the startup torque over the ramp
    ``r`` (:data:`~wresdyn.robot.servo.STARTUP_RAMP`), ``beta`` the backlash, ``o`` the encoder offset (both 0:
    the same values as without them, bit for bit)."""
    err = e.let(f"{tq} - ({q} + {off})")
    err_m = e.let(f"{err} - wp.clamp({err}, -{bl}, {bl})")
    contact = e.let(f"wp.where({bl} > S(0.0), wp.min(wp.abs({err_m}) * S({1.0 / STARTUP_RAMP!r}), S(1.0)), S(1.0))")
    err_b = e.let(f"{err_m} - wp.clamp({err_m}, -{db}, {db})")
    ramp = e.let(f"{err_b} * S({1.0 / STARTUP_RAMP!r})")
    raw = e.let(f"{ke} * {err_b} + {u0} * wp.clamp({ramp}, S(-1.0), S(1.0)) + {kd} * ({tqd} - {qd})")
    duty = e.let(f"wp.clamp({raw}, -{eff}, {eff})")
    w0_safe = e.let(f"wp.where({w0} > S(0.0), {w0}, S(1.0))")  # no division by 0 in the branch not taken
    emf = e.let(f"wp.where({w0} > S(0.0), {eff} / {w0_safe}, S(0.0))")
    out = e.let(f"{duty} - {emf} * {qd}")
    tau = e.let(f"{contact} * wp.clamp({out}, -{eff}, {eff})")
    free_u = e.let(f"wp.where(wp.abs({raw}) < {eff}, S(1.0), S(0.0))")
    free_t = e.let(f"{contact} * wp.where(wp.abs({out}) < {eff}, S(1.0), S(0.0))")  # out of mesh: no derivative
    outside = e.let(f"wp.where(wp.abs({err_m}) > {db}, S(1.0), S(0.0))")
    stiff = e.let(f"{ke} + wp.where(wp.abs({ramp}) < S(1.0), {u0} * S({1.0 / STARTUP_RAMP!r}), S(0.0))")
    return tau, e.let(f"{free_t} * ({free_u} * {kd} + {emf})"), e.let(f"{free_t} * {free_u} * {outside} * {stiff}")
