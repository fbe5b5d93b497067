"""Rigid-body dynamics of one robot as generated straight-line code: FK, RNEA, CRBA and the tree solve.

All spatial quantities are in world axes about the fixed base (``ReplayTree.origin``):

1. forward kinematics and motion subspaces ``S_k`` (revolute: ``[a; o x a]``, prismatic: ``[0; a]``);
2. RNEA for the bias ``c(q, qd) = C qd + g`` (Featherstone, RBDA Table 5.1, base acceleration ``-g``);
3. CRBA for ``M(q)`` with composite inertias summed in world axes (RBDA Table 6.2), so each
   off-diagonal entry is one 6-vector dot product;
4. ``H = L^T D L`` factorisation without fill-in for a branched tree (RBDA Table 6.3) and the solve.

Link masses, centres of mass and inertias are read from the model's per-world body arrays
(:func:`inertial_params`); only the joint frames, axes and the poses of welded bodies are folded in.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .emit import Emitter, Sym
from .tree import ReplayTree

__all__ = ["Group", "dynamics", "inertial_params", "solve_ltdl"]

_ZERO3 = [0.0, 0.0, 0.0]


def _joint_rotation(e: Emitter, axis: np.ndarray, c: str, s: str, omc: str):
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


def _rotate_sym(e: Emitter, R, inertia) -> list:
    """R I R^T for a symmetric I, upper triangle computed and mirrored."""
    t = e.mm(R, inertia)
    out = [[None] * 3 for _ in range(3)]
    for i in range(3):
        for j in range(i, 3):
            out[i][j] = out[j][i] = e.sp(*[(t[i][n], R[j][n]) for n in range(3)])
    return out


def _mat(a: np.ndarray) -> list:
    return [[float(x) for x in row] for row in a]


class _Spatial:
    """Spatial inertia in world axes about the origin: mass ``m``, first moment ``h = m c``, rotational
    inertia ``J`` about the origin."""

    def __init__(self, m: Sym, h: list, J: list):
        self.m, self.h, self.J = m, h, J

    def apply(self, e: Emitter, w: list, v: list):
        """I [w; v] = [J w + h x v; m v - h x w]."""
        jw = e.mv(self.J, w)
        hv = e.cross(self.h, v)
        hw = e.cross(self.h, w)
        ang = [e.sp((jw[i],), (hv[i],)) for i in range(3)]
        return ang, [e.sp((self.m, v[i]), (-1.0, hw[i])) for i in range(3)]

    def plus(self, e: Emitter, o: "_Spatial") -> "_Spatial":
        return _Spatial(e.sp((self.m,), (o.m,)), e.add(self.h, o.h), [e.add(self.J[i], o.J[i]) for i in range(3)])


@dataclass
class Group:
    """A DoF's rigid group in its body frame, as symbols of the kernel prologue.

    ``about_com``: one body; ``first`` is its centre of mass ``c`` [m] and ``second`` its inertia about
    ``c``. Otherwise (welded bodies): ``first`` is the first moment ``h = sum m_b c_b`` [kg m] and ``second``
    the inertia about the body frame origin, so no division by a mass that may be zero is needed.
    """

    mass: Sym
    first: list
    second: list
    about_com: bool


def inertial_params(e: Emitter, tree: ReplayTree) -> list[Group | None]:
    """Emit loads of ``body_mass/com/inertia[bb + b]`` and compose each DoF's rigid group in its body frame.

    Runs once per launch (before the time loop of the rollout kernel). The inertia is symmetrised,
    ``(I + I^T) / 2``, so its gradient is split evenly between ``I_ij`` and ``I_ji``. Welded bodies enter
    with their constant pose ``(R, p)`` in the DoF's body frame: ``c' = R c + p``, ``I' = R I R^T``, and
    the group is ``m = sum m_b``, ``h = sum m_b c'_b``, ``J_o = sum I'_b + m_b (|c'_b|^2 1 - c'_b c'_b^T)``.
    Every entry is read, zero or not, so the code depends on the tree alone and any inertial values reuse it.
    """
    out: list[Group | None] = []
    for k in range(tree.n_dof):
        parts = []
        for b in tree.group(k):
            m = e.let(f"body_mass[bb + {b}]", prefix=f"pm{b}_")
            cv = e.let(f"body_com[bb + {b}]", prefix=f"pcv{b}_")
            c = [e.let(f"{cv}[{i}]", prefix=f"pc{b}_") for i in range(3)]
            iv = e.let(f"body_inertia[bb + {b}]", prefix=f"piv{b}_")
            inertia = [[0.0] * 3 for _ in range(3)]
            for i in range(3):
                inertia[i][i] = e.let(f"{iv}[{i}, {i}]", prefix=f"pi{b}_")
                for j in range(i + 1, 3):
                    inertia[i][j] = inertia[j][i] = e.let(f"S(0.5) * ({iv}[{i}, {j}] + {iv}[{j}, {i}])",
                                                          prefix=f"pi{b}_")
            rot, pos = _mat(tree.rot_db[b]), [float(x) for x in tree.pos_db[b]]
            parts.append((m, e.add(e.mv(rot, c), pos), _rotate_sym(e, rot, inertia)))
        if not parts:
            out.append(None)
        elif len(parts) == 1:
            out.append(Group(*parts[0], about_com=True))
        else:
            mass = e.sp(*[(m,) for m, _, _ in parts])
            first = [e.sp(*[(m, c[i]) for m, c, _ in parts]) for i in range(3)]
            second = [[None] * 3 for _ in range(3)]
            for i in range(3):
                for j in range(i, 3):
                    terms = []
                    for m, c, inertia in parts:
                        terms.append((inertia[i][j],))
                        if i == j:
                            terms += [(m, c[o], c[o]) for o in range(3) if o != i]
                        else:
                            terms.append((-1.0, m, c[i], c[j]))
                    second[i][j] = second[j][i] = e.sp(*terms)
            out.append(Group(mass, first, second, about_com=False))
    return out


def _body_inertia(e: Emitter, group: Group | None, R, p) -> _Spatial:
    """Spatial inertia of a DoF's rigid group in world axes about the origin, its body frame at ``(R, p)``."""
    if group is None:
        return _Spatial(0.0, _ZERO3[:], [_ZERO3[:], _ZERO3[:], _ZERO3[:]])
    m = group.mass
    J = [[None] * 3 for _ in range(3)]
    iw = _rotate_sym(e, R, group.second)
    if group.about_com:
        # parallel axis to the origin: J = R I_c R^T + m (|c|^2 1 - c c^T), c = p + R c_body, h = m c
        c = e.add(p, e.mv(R, group.first))
        h = e.scale(c, m)
        for i in range(3):
            for j in range(i, 3):
                if i == j:
                    J[i][i] = e.sp((iw[i][i],), *[(h[o], c[o]) for o in range(3) if o != i])
                else:
                    J[i][j] = J[j][i] = e.sp((iw[i][j],), (-1.0, h[i], c[j]))
        return _Spatial(m, h, J)
    # about the body origin p: h = m p + h', J = R J_o R^T + m (|p|^2 1 - p p^T) + 2 (p.h') 1 - p h'^T - h' p^T,
    # h' = R h_body (expand |p + y|^2 1 - (p + y)(p + y)^T over the group's mass points y)
    hr = e.mv(R, group.first)
    mp = e.scale(p, m)
    ph = e.sp(*[(p[o], hr[o]) for o in range(3)])
    for i in range(3):
        for j in range(i, 3):
            if i == j:
                J[i][i] = e.sp((iw[i][i],), *[(mp[o], p[o]) for o in range(3) if o != i], (2.0, ph),
                               (-2.0, p[i], hr[i]))
            else:
                J[i][j] = J[j][i] = e.sp((iw[i][j],), (-1.0, mp[i], p[j]), (-1.0, p[i], hr[j]), (-1.0, hr[i], p[j]))
    return _Spatial(m, e.add(mp, hr), J)


def _cross_motion(e, w, v, w2, v2):
    """[w; v] x [w2; v2] = [w x w2; w x v2 + v x w2]."""
    a = e.cross(w, w2)
    b = e.add(e.cross(w, v2), e.cross(v, w2))
    return a, b


def _cross_force(e, w, v, n, f):
    """[w; v] x* [n; f] = [w x n + v x f; w x f]."""
    return e.add(e.cross(w, n), e.cross(v, f)), e.cross(w, f)


def dynamics(e: Emitter, tree: ReplayTree, groups: list, q: list[str], qd: list[str], g: list[str]):
    """Emit FK, RNEA and CRBA. Returns (bias, M_diag, M_off) with M_off[(k, j)] for j an ancestor of k."""
    n = tree.n_dof
    ident = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    R, P, Sw, Sv, V, A, I = [None] * n, [None] * n, [None] * n, [None] * n, [None] * n, [None] * n, [None] * n
    F: list = [None] * n
    for k in range(n):
        e.mark(f"dof {k}: kinematics, velocity, bias acceleration, RNEA body force")
        par = int(tree.parent[k])
        rp, pp = (ident, _ZERO3) if par < 0 else (R[par], P[par])
        rj = e.mm(rp, _mat(tree.rot_pj[k]))
        o = e.add(pp, e.mv(rp, [float(x) for x in tree.pos_pj[k]]))
        axis = [float(x) for x in tree.axis[k]]
        aw = e.mv(rj, axis)
        rot_jc = _mat(tree.rot_jc[k])
        pos_jc = [float(x) for x in tree.pos_jc[k]]
        if tree.prismatic[k]:
            R[k] = e.mm(rj, rot_jc)
            P[k] = e.add(o, e.mv(rj, [e.sp((axis[i], q[k]), const=pos_jc[i]) for i in range(3)]))
            Sw[k], Sv[k] = _ZERO3[:], aw
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
            A[k] = (_ZERO3[:], [e.sp((-1.0, g[i])) for i in range(3)])
        else:
            V[k] = (e.add(V[par][0], sqw), e.add(V[par][1], sqv))
            # dS/dt qd = V_parent x S qd (= V_k x S qd, since S qd x S qd = 0)
            cw, cv = _cross_motion(e, V[par][0], V[par][1], sqw, sqv)
            A[k] = (e.add(A[par][0], cw), e.add(A[par][1], cv))
        I[k] = _body_inertia(e, groups[k], R[k], P[k])
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


def solve_ltdl(e: Emitter, tree: ReplayTree, h_diag: list, h_off: dict, rhs: list) -> list:
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
