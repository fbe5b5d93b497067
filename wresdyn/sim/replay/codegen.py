"""Generate the replay kernels for one robot: straight-line Warp code with the robot's constants folded in.

Warp differentiates a kernel by replaying it, which is exact for straight-line code (every value is a
fresh SSA variable) but not for loops that mutate local arrays. So instead of a generic kernel that walks
the tree with loops, this module unrolls the recursive algorithms for the robot at hand and writes them
out as scalar Python/Warp statements, folding every constant that is 0 or +-1 (axis-aligned joints,
identity joint frames) at generation time. The CPU backend runs one world per thread serially, so fewer
flops per world is directly more env-steps/s.

One world step, all spatial quantities in world axes about the fixed base (``ReplayTree.origin``):

1. forward kinematics and motion subspaces ``S_k`` (revolute: ``[a; o x a]``, prismatic: ``[0; a]``);
2. RNEA for the bias ``c(q, qd) = C qd + g`` (Featherstone, RBDA Table 5.1, base acceleration ``-g``);
3. CRBA for ``M(q)`` with composite inertias summed in world axes (RBDA Table 6.2), so each
   off-diagonal entry is one 6-vector dot product;
4. drive, passive and limit torques, and the implicit diagonal (see :mod:`wresdyn.sim.replay.solver`);
5. ``H = L^T D L`` factorisation without fill-in for a branched tree (RBDA Table 6.3) and the solve;
6. semi-implicit Euler: ``qd' = qd + dt qdd``, ``q' = q + dt qd'``.
"""

from __future__ import annotations

import re

import numpy as np

from .tree import ReplayTree

__all__ = ["generate_source"]

Sym = float | str
"""A scalar at generation time: a Python float is a constant, a string names a kernel variable."""

_MARK = "#@ "


class _Emitter:
    """Writes SSA statements and folds constants (products with 0 vanish, with +-1 are free)."""

    def __init__(self):
        self.lines: list[str] = []
        self._count = 0

    def const(self, x: float) -> str:
        return f"S({float(x)!r})"

    def sym(self, x: Sym) -> str:
        if isinstance(x, str):
            return f"({x})" if x.startswith("-") else x
        return self.const(x)

    def let(self, expr: str, prefix: str = "t") -> str:
        self._count += 1
        name = f"{prefix}{self._count}"
        self.lines.append(f"{name} = {expr}")
        return name

    def mark(self, text: str) -> None:
        """A place where the statement list may be cut into functions (see :func:`_outline`)."""
        self.lines.append(f"{_MARK}{text}")

    def sp(self, *terms: tuple, const: float = 0.0) -> Sym:
        """Sum of products; each term is a tuple of factors (floats or variable names)."""
        parts: list[tuple[float, list[str]]] = []
        for term in terms:
            coef, names = 1.0, []
            for f in term:
                if isinstance(f, str):
                    if f.startswith("-"):  # a folded negation: "-t12"
                        coef, f = -coef, f[1:]
                    names.append(f)
                else:
                    coef *= float(f)
            if coef == 0.0:
                continue
            if not names:
                const += coef
            else:
                parts.append((coef, names))
        if not parts:
            return float(const)
        if len(parts) == 1 and abs(parts[0][0]) == 1.0 and len(parts[0][1]) == 1 and const == 0.0:
            return ("" if parts[0][0] > 0.0 else "-") + parts[0][1][0]  # no statement for +-x
        expr = ""
        for i, (coef, names) in enumerate(parts):
            neg = coef < 0.0
            mag = abs(coef)
            body = "*".join(names) if mag == 1.0 else self.const(mag) + "*" + "*".join(names)
            expr += ("-" if neg else "") + body if i == 0 else (" - " if neg else " + ") + body
        if const != 0.0:
            expr += (" - " if const < 0.0 else " + ") + self.const(abs(const))
        return self.let(expr)

    # 3-vectors and 3x3 matrices as lists of Sym
    def add(self, a, b):
        return [self.sp((a[i],), (b[i],)) for i in range(len(a))]

    def scale(self, a, s):
        return [self.sp((a[i], s)) for i in range(len(a))]

    def cross(self, a, b):
        return [
            self.sp((a[1], b[2]), (-1.0, a[2], b[1])),
            self.sp((a[2], b[0]), (-1.0, a[0], b[2])),
            self.sp((a[0], b[1]), (-1.0, a[1], b[0])),
        ]

    def mv(self, m, v):
        return [self.sp(*[(m[i][k], v[k]) for k in range(3)]) for i in range(3)]

    def mm(self, a, b):
        return [[self.sp(*[(a[i][k], b[k][j]) for k in range(3)]) for j in range(3)] for i in range(3)]


def _joint_rotation(e: _Emitter, axis: np.ndarray, c: str, s: str, omc: str):
    """R(a, q) = I + sin q [a]x + (1 - cos q) [a]x^2, entries folded for the constant axis ``a``."""
    a = [float(x) for x in axis]
    k = [[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]]
    k2 = [[a[i] * a[j] - (1.0 if i == j else 0.0) for j in range(3)] for i in range(3)]
    out = []
    for i in range(3):
        row = []
        for j in range(3):
            if i == j and k2[i][j] == -1.0:
                row.append(c)  # 1 - (1 - cos q)
            else:
                row.append(e.sp((1.0 if i == j else 0.0,), (k[i][j], s), (k2[i][j], omc)))
        out.append(row)
    return out


class _Spatial:
    """Spatial inertia in world axes about the origin: mass ``m``, first moment ``h = m c``, rotational
    inertia ``J`` about the origin."""

    def __init__(self, m: Sym, h: list, J: list):
        self.m, self.h, self.J = m, h, J

    def apply(self, e: _Emitter, w: list, v: list):
        """I [w; v] = [J w + h x v; m v - h x w]."""
        jw = e.mv(self.J, w)
        hv = e.cross(self.h, v)
        hw = e.cross(self.h, w)
        ang = [e.sp((jw[i],), (hv[i],)) for i in range(3)]
        return ang, [e.sp((self.m, v[i]), (-1.0, hw[i])) for i in range(3)]

    def plus(self, e: _Emitter, o: "_Spatial") -> "_Spatial":
        return _Spatial(e.sp((self.m,), (o.m,)), e.add(self.h, o.h), [e.add(self.J[i], o.J[i]) for i in range(3)])


def _body_inertia(e: _Emitter, tree: ReplayTree, k: int, R, p) -> _Spatial:
    """Spatial inertia of DoF ``k``'s body in world axes about the origin."""
    m = float(tree.mass[k])
    if m <= 0.0:
        z = [0.0, 0.0, 0.0]
        return _Spatial(0.0, z, [z[:], z[:], z[:]])
    c = e.add(p, e.mv(R, [float(x) for x in tree.com[k]]))
    ib = [[float(x) for x in row] for row in tree.inertia[k]]
    if np.allclose(tree.inertia[k], tree.inertia[k][0, 0] * np.eye(3), rtol=0.0, atol=1e-12):
        iw = ib  # isotropic: R I R^T = I
    else:
        t = e.mm(R, ib)
        iw = [[None] * 3 for _ in range(3)]
        for i in range(3):
            for j in range(i, 3):
                iw[i][j] = e.sp(*[(t[i][n], R[j][n]) for n in range(3)])
                iw[j][i] = iw[i][j]
    # parallel axis to the origin: J = I_c + m (|c|^2 1 - c c^T)
    J = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i, 3):
            if i == j:
                o1, o2 = [n for n in range(3) if n != i]
                J[i][i] = e.sp((iw[i][i],), (m, c[o1], c[o1]), (m, c[o2], c[o2]))
            else:
                J[i][j] = e.sp((iw[i][j],), (-m, c[i], c[j]))
                J[j][i] = J[i][j]
    return _Spatial(m, e.scale(c, m), J)


def _cross_motion(e, w, v, w2, v2):
    """[w; v] x [w2; v2] = [w x w2; w x v2 + v x w2]."""
    a = e.cross(w, w2)
    b = e.add(e.cross(w, v2), e.cross(v, w2))
    return a, b


def _cross_force(e, w, v, n, f):
    """[w; v] x* [n; f] = [w x n + v x f; w x f]."""
    return e.add(e.cross(w, n), e.cross(v, f)), e.cross(w, f)


def _dynamics(e: _Emitter, tree: ReplayTree, q: list[str], qd: list[str], g: list[str]):
    """Emit FK, RNEA and CRBA. Returns (bias, M_diag, M_off) with M_off[(k, j)] for j an ancestor of k."""
    n = tree.n_dof
    ident = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    R, P, Sw, Sv, V, A, I = [None] * n, [None] * n, [None] * n, [None] * n, [None] * n, [None] * n, [None] * n
    F: list = [None] * n
    for k in range(n):
        e.mark(f"dof {k}: kinematics, velocity, bias acceleration, RNEA body force")
        par = int(tree.parent[k])
        rp, pp = (ident, [0.0, 0.0, 0.0]) if par < 0 else (R[par], P[par])
        rot_pj = [[float(x) for x in row] for row in tree.rot_pj[k]]
        rj = e.mm(rp, rot_pj)
        o = e.add(pp, e.mv(rp, [float(x) for x in tree.pos_pj[k]]))
        axis = [float(x) for x in tree.axis[k]]
        aw = e.mv(rj, axis)
        rot_jc = [[float(x) for x in row] for row in tree.rot_jc[k]]
        pos_jc = [float(x) for x in tree.pos_jc[k]]
        if tree.prismatic[k]:
            R[k] = e.mm(rj, rot_jc)
            P[k] = e.add(o, e.mv(rj, [e.sp((axis[i], q[k]), const=pos_jc[i]) for i in range(3)]))
            Sw[k], Sv[k] = [0.0, 0.0, 0.0], aw
        else:
            c = e.let(f"wp.cos({q[k]})")
            s = e.let(f"wp.sin({q[k]})")
            omc = e.sp((-1.0, c), const=1.0)
            rq = e.mm(rj, _joint_rotation(e, tree.axis[k], c, s, omc))
            R[k] = e.mm(rq, rot_jc)
            P[k] = e.add(o, e.mv(rq, pos_jc))
            Sw[k], Sv[k] = aw, e.cross(o, aw)
        sqw, sqv = e.scale(Sw[k], qd[k]), e.scale(Sv[k], qd[k])
        if par < 0:
            V[k] = (sqw, sqv)
            A[k] = ([0.0, 0.0, 0.0], [e.sp((-1.0, g[i])) for i in range(3)])
        else:
            V[k] = (e.add(V[par][0], sqw), e.add(V[par][1], sqv))
            # dS/dt qd = V_parent x S qd (= V_k x S qd, since S qd x S qd = 0)
            cw, cv = _cross_motion(e, V[par][0], V[par][1], sqw, sqv)
            A[k] = (e.add(A[par][0], cw), e.add(A[par][1], cv))
        I[k] = _body_inertia(e, tree, k, R[k], P[k])
        ia = I[k].apply(e, *A[k])
        iv = I[k].apply(e, *V[k])
        xw, xv = _cross_force(e, V[k][0], V[k][1], iv[0], iv[1])
        F[k] = (e.add(ia[0], xw), e.add(ia[1], xv))
    Ic = list(I)
    bias: list = [None] * n
    m_diag: list = [None] * n
    m_off: dict = {}
    for k in reversed(range(n)):
        e.mark(f"dof {k}: RNEA and CRBA, leaves to root")
        par = int(tree.parent[k])
        bias[k] = e.sp(*[(Sw[k][i], F[k][0][i]) for i in range(3)], *[(Sv[k][i], F[k][1][i]) for i in range(3)])
        fw, fv = Ic[k].apply(e, Sw[k], Sv[k])
        m_diag[k] = e.sp(*[(Sw[k][i], fw[i]) for i in range(3)], *[(Sv[k][i], fv[i]) for i in range(3)])
        for j in tree.ancestors(k):
            m_off[(k, j)] = e.sp(*[(Sw[j][i], fw[i]) for i in range(3)], *[(Sv[j][i], fv[i]) for i in range(3)])
        if par >= 0:
            F[par] = (e.add(F[par][0], F[k][0]), e.add(F[par][1], F[k][1]))
            Ic[par] = Ic[par].plus(e, Ic[k])
    return bias, m_diag, m_off


def _solve(e: _Emitter, tree: ReplayTree, h_diag: list, h_off: dict, rhs: list) -> list:
    """Solve H x = rhs with H = L^T D L, no fill-in for a tree (RBDA Table 6.3), fully unrolled."""
    n = tree.n_dof
    anc = [tree.ancestors(k) for k in range(n)]
    pend: dict = {}
    hd = list(h_diag)
    ho = dict(h_off)
    lo: dict = {}
    inv_d: list = [None] * n
    for k in reversed(range(n)):
        e.mark(f"dof {k}: factorise")
        hd[k] = e.sp((hd[k],), *pend.pop((k, k), []))
        for j in anc[k]:
            ho[(k, j)] = e.sp((ho[(k, j)],), *pend.pop((k, j), []))
        inv_d[k] = e.let(f"S(1.0) / {e.sym(hd[k])}")
        for i in anc[k]:
            a = e.sp((ho[(k, i)], inv_d[k]))
            lo[(k, i)] = a
            pend.setdefault((i, i), []).append((-1.0, a, ho[(k, i)]))
            for j in anc[i]:
                pend.setdefault((i, j), []).append((-1.0, a, ho[(k, j)]))
    e.mark("solve")
    x = list(rhs)
    back: dict = {}
    for i in reversed(range(n)):
        x[i] = e.sp((x[i],), *back.pop(i, []))
        for j in anc[i]:
            back.setdefault(j, []).append((-1.0, lo[(i, j)], x[i]))
    x = [e.sp((x[i], inv_d[i])) for i in range(n)]
    for i in range(n):
        x[i] = e.sp((x[i],), *[(-1.0, lo[(i, j)], x[j]) for j in anc[i]])
    return x


_PARAMS = ("ke", "kd", "arm", "fric", "damp", "eff", "lo", "hi", "lke", "lkd")
"""Per-DoF model arrays the kernels read: drive gains, armature, friction, damping, effort, limits."""


def _load_params(e: _Emitter, tree: ReplayTree) -> dict:
    out = {}
    for name in _PARAMS:
        out[name] = [e.let(f"{name}[bd + {int(tree.qd_offset[k])}]", prefix=f"p{name}_") for k in range(tree.n_dof)]
    return out


def _step(e: _Emitter, tree: ReplayTree, p: dict, q, qd, tq, tqd, jf, g) -> tuple[list, list]:
    """Emit one world step; returns the new (q, qd) symbols."""
    n = tree.n_dof
    bias, m_diag, m_off = _dynamics(e, tree, q, qd, g)
    rhs, h_diag = [], []
    for k in range(n):
        e.mark(f"dof {k}: drive, passive and limit torques; implicit diagonal")
        ke, kd, arm, fric, damp, eff, lo, hi, lke, lkd = (p[name][k] for name in _PARAMS)
        raw = e.let(f"{ke} * ({tq[k]} - {q[k]}) + {kd} * ({tqd[k]} - {qd[k]})")
        eff = e.let(f"wp.where({eff} > S(0.0), {eff}, S(1.0e30))")  # importers write 0 for "no limit"
        pd = e.let(f"wp.clamp({raw}, -{eff}, {eff})")
        free = e.let(f"wp.where(wp.abs({raw}) < {eff}, S(1.0), S(0.0))")  # saturated: no velocity derivative
        th = e.let(f"wp.tanh({qd[k]} / friction_vel)")
        viol = e.let(f"wp.where({q[k]} < {lo}, {lo} - {q[k]}, wp.where({q[k]} > {hi}, {hi} - {q[k]}, S(0.0)))")
        on = e.let(f"wp.where({q[k]} < {lo}, S(1.0), wp.where({q[k]} > {hi}, S(1.0), S(0.0)))")
        damp_k = e.let(f"{free} * {kd} + {damp} + {fric} * (S(1.0) - {th} * {th}) / friction_vel + {on} * {lkd}")
        stiff_k = e.let(f"kp_implicit * {free} * {ke} + {on} * {lke}")
        rhs.append(e.let(
            f"{pd} + {jf[k]} - {e.sym(bias[k])} - {damp} * {qd[k]} - {fric} * {th} + {lke} * {viol}"
            f" - {on} * {lkd} * {qd[k]} - dt * {stiff_k} * {qd[k]}"
        ))
        h_diag.append(e.let(f"{e.sym(m_diag[k])} + {arm} + dt * {damp_k} + dt * dt * {stiff_k}"))
    qdd = _solve(e, tree, h_diag, m_off, rhs)
    e.mark("semi-implicit Euler")
    qd_new = [e.let(f"{qd[k]} + dt * {e.sym(qdd[k])}") for k in range(n)]
    q_new = [e.let(f"{q[k]} + dt * {qd_new[k]}") for k in range(n)]
    return q_new, qd_new


_IDENT = re.compile(r"(?<![\w.])[A-Za-z_]\w*")
_KERNEL_SCALARS = ("dt", "friction_vel", "kp_implicit")
"""Kernel arguments the step statements read."""


def _outline(lines: list[str], prefix: str, inline: bool | None, after: list[str], external: set[str],
             min_len: int = 500) -> tuple[list[str], list[str]]:
    """Cut a straight-line statement list into ``@wp.func`` chunks of at least ``min_len`` statements.

    Clang compiles one huge function superlinearly: the humanoid step's adjoint as one function took two
    minutes at -O1, as seven non-inlined functions 16 s at -O2 (and ran faster than with 20). Each chunk
    takes the values it reads as arguments and returns the values read later (``after``: the statements
    that follow, e.g. array stores; ``external``: kernel variables defined before). Returns (function
    sources, kernel statements).
    """
    chunks: list[list[str]] = [[]]
    for line in lines:
        if line.startswith(_MARK):
            if len(chunks[-1]) >= min_len:
                chunks.append([])
            continue
        chunks[-1].append(line)
    parsed = [[(lhs, _IDENT.findall(rhs)) for lhs, rhs in (line.split(" = ", 1) for line in chunk)] for chunk in chunks]
    defined = {lhs for stmts in parsed for lhs, _ in stmts}
    last_use: dict[str, int] = {}
    for c, stmts in enumerate(parsed):
        for _, uses in stmts:
            for u in uses:
                last_use[u] = c
    for line in after:
        for u in _IDENT.findall(line.split(" = ", 1)[1]):
            last_use[u] = len(parsed)
    hint = "" if inline is None else f"(inline={inline})"
    funcs, body = [], []
    for c, (chunk, stmts) in enumerate(zip(chunks, parsed)):
        own = {lhs for lhs, _ in stmts}
        ins: list[str] = []
        for _, uses in stmts:
            for u in uses:
                if u not in own and u not in ins and (u in defined or u in external or u in _KERNEL_SCALARS):
                    ins.append(u)
        outs = [lhs for lhs, _ in stmts if last_use.get(lhs, -1) > c]
        if not outs:
            continue
        name = f"{prefix}{c}"
        args = ", ".join(f"{a}: S" for a in ins)
        funcs.append(f"@wp.func{hint}\ndef {name}({args}):\n" + _indent(chunk, 1) + f"\n    return {', '.join(outs)}\n")
        body.append(f"{', '.join(outs)} = {name}({', '.join(ins)})")
    return funcs, body


def _indent(lines: list[str], depth: int) -> str:
    pad = "    " * depth
    return "\n".join(pad + line for line in lines)


_HEADER = '''"""Generated by wresdyn.sim.replay.codegen for robot tree {digest} ({n} DoF, {scalar}); do not edit."""
import warp as wp

S = wp.{scalar}
V3 = wp.vec3{suffix}
'''

_PARAM_ARGS = ", ".join(f"{name}: wp.array(dtype=S)" for name in _PARAMS)
_GRAVITY = ["g = gravity[w]", "gx = g[0]", "gy = g[1]", "gz = g[2]"]

_FLAT = {"q": "joint_q[bq + {}]", "qd": "joint_qd[bd + {}]", "tq": "target_q[bd + {}]",
         "tqd": "target_qd[bd + {}]", "jf": "joint_f[bd + {}]", "q_out": "joint_q_out[bq + {}]",
         "qd_out": "joint_qd_out[bd + {}]"}
"""Array accesses of the step kernel (Newton's flat per-world layout)."""
_TIME_MAJOR = {"q": "q[t, w, {}]", "qd": "qd[t, w, {}]", "tq": "target_q[t, w, {}]", "tqd": "target_qd[t, w, {}]",
               "jf": "joint_f[t, w, {}]", "q_out": "q[t + 1, w, {}]", "qd_out": "qd[t + 1, w, {}]"}
"""Array accesses of the rollout kernel (time, world, coordinate)."""


def _step_code(tree: ReplayTree, access: dict) -> tuple[list[str], list[str], list[str], list[str]]:
    """Statements of one step: (parameter loads, state and control loads, compute, stores)."""
    n = tree.n_dof
    co = [int(x) for x in tree.q_offset]
    do = [int(x) for x in tree.qd_offset]
    e = _Emitter()
    p = _load_params(e, tree)
    params, e.lines = e.lines + _GRAVITY, []
    q = [e.let(access["q"].format(co[k]), prefix="q_") for k in range(n)]
    qd, tq, tqd, jf = ([e.let(access[kind].format(do[k]), prefix=f"{kind}_") for k in range(n)]
                       for kind in ("qd", "tq", "tqd", "jf"))
    loads, e.lines = e.lines, []
    qn, qdn = _step(e, tree, p, q, qd, tq, tqd, jf, ["gx", "gy", "gz"])
    stores = [f"{access['q_out'].format(co[k])} = {qn[k]}" for k in range(n)]
    stores += [f"{access['qd_out'].format(do[k])} = {qdn[k]}" for k in range(n)]
    return params, loads, e.lines, stores


def _unmarked(lines: list[str]) -> list[str]:
    return [x for x in lines if not x.startswith(_MARK)]


def generate_source(tree: ReplayTree, scalar: str = "float32", backward: bool = True,
                    inline: bool | None = False) -> str:
    """Python source of a module with kernels ``replay_step``, ``replay_rollout`` and ``replay_terms``.

    ``replay_step`` advances one step on Newton's flat ``joint_q``/``joint_qd`` arrays (one thread per
    world). ``replay_rollout`` runs ``n_steps`` steps in one launch (forward only) on time-major
    trajectories (time, world, coordinate), whose row ``t`` is laid out like Newton's ``joint_q``, so its
    adjoint is the step kernel's adjoint launched on rows ``t`` and ``t + 1``. ``replay_terms`` writes
    ``M(q)`` and ``c(q, qd)`` for the parity tests. With ``backward`` the step kernel gets an adjoint; its
    code is cut into functions with the given ``inline`` hint (see :func:`_outline`).
    """
    n = tree.n_dof
    src = [_HEADER.format(digest=tree.digest(), n=n, scalar=scalar, suffix="d" if scalar == "float64" else "f")]

    params, loads, compute, stores = _step_code(tree, _FLAT)
    if backward:
        external = {x.split(" = ", 1)[0] for x in params + loads}
        funcs, compute = _outline(compute, "step_part", inline, stores, external)
        src += funcs
    src.append(f'''
@wp.kernel(enable_backward={backward}, module="unique")
def replay_step(
    world_start: int, dt: S, friction_vel: S, kp_implicit: S, {_PARAM_ARGS}, gravity: wp.array(dtype=V3),
    joint_q: wp.array(dtype=S), joint_qd: wp.array(dtype=S), target_q: wp.array(dtype=S),
    target_qd: wp.array(dtype=S), joint_f: wp.array(dtype=S),
    joint_q_out: wp.array(dtype=S), joint_qd_out: wp.array(dtype=S),
):
    w = wp.tid() + world_start
    bq = w * {tree.coords_per_world}
    bd = w * {tree.dofs_per_world}
{_indent(params + loads + _unmarked(compute) + stores, 1)}
''')

    params, loads, compute, stores = _step_code(tree, _TIME_MAJOR)
    src.append(f'''
@wp.kernel(enable_backward=False, module="unique")
def replay_rollout(
    world_start: int, n_steps: int, dt: S, friction_vel: S, kp_implicit: S, {_PARAM_ARGS},
    gravity: wp.array(dtype=V3), target_q: wp.array3d(dtype=S), target_qd: wp.array3d(dtype=S),
    joint_f: wp.array3d(dtype=S),
    q: wp.array3d(dtype=S), qd: wp.array3d(dtype=S),
):
    w = wp.tid() + world_start
    bd = w * {tree.dofs_per_world}
{_indent(params, 1)}
    for t in range(n_steps):
{_indent(loads + _unmarked(compute) + stores, 2)}
''')

    e = _Emitter()
    e.lines += _GRAVITY
    q = [e.let(f"q[w, {k}]", prefix="q_") for k in range(n)]
    qd = [e.let(f"qd[w, {k}]", prefix="qd_") for k in range(n)]
    bias, m_diag, m_off = _dynamics(e, tree, q, qd, ["gx", "gy", "gz"])
    for k in range(n):
        e.lines.append(f"bias[w, {k}] = {e.sym(bias[k])}")
        e.lines.append(f"mass_matrix[w, {k}, {k}] = {e.sym(m_diag[k])}")
    for (k, j), v in m_off.items():
        e.lines.append(f"mass_matrix[w, {k}, {j}] = {e.sym(v)}")
        e.lines.append(f"mass_matrix[w, {j}, {k}] = {e.sym(v)}")
    src.append(f'''
@wp.kernel(enable_backward=False, module="unique")
def replay_terms(
    gravity: wp.array(dtype=V3), q: wp.array2d(dtype=S), qd: wp.array2d(dtype=S),
    mass_matrix: wp.array3d(dtype=S), bias: wp.array2d(dtype=S),
):
    w = wp.tid()
{_indent(_unmarked(e.lines), 1)}
''')
    return "\n".join(src)
