"""Straight-line Warp code as text: an SSA emitter that folds constants, and outlining into functions.

Warp differentiates a kernel by replaying it, which is exact for straight-line code (every value is a
fresh SSA variable) but not for loops that mutate local arrays; :mod:`.codegen` therefore unrolls the
robot's recursive algorithms into scalar statements written by :class:`Emitter`, folding every constant
that is 0 or +-1 at generation time.
"""

from __future__ import annotations

import re

__all__ = ["Emitter", "Sym", "branched", "gate", "indent", "outline", "unmarked"]

Sym = float | str
"""A scalar at generation time: a Python float is a constant, a string names a kernel variable."""

_MARK = "#@ "


class Emitter:
    """Writes SSA statements and folds constants (products with 0 vanish, with +-1 are free)."""

    def __init__(self, start: int = 0):
        """``start``: names are numbered from it on, so that emitters sharing a kernel do not reuse them."""
        self.lines: list[str] = []
        self._count = int(start)

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
        """A place where the statement list may be cut into functions (see :func:`outline`)."""
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

_IDENT = re.compile(r"(?<![\w.])[A-Za-z_]\w*")
_IF, _ENDIF = f"{_MARK}if ", f"{_MARK}endif"


def gate(lines: list[str], cond: str) -> list[str]:
    """Mark ``lines`` as run only where the kernel variable ``cond`` holds (a run-time branch): their last
    statements may reassign names defined before them, the values the branch hands on (:func:`branched`,
    :func:`outline`)."""
    return [f"{_IF}{cond}", *lines, _ENDIF]


def branched(lines: list[str]) -> list[str]:
    """The statements with each :func:`gate` region written as an ``if`` block, without outlining marks."""
    out: list[str] = []
    cond = None
    for line in lines:
        if line.startswith(_IF):
            cond = line[len(_IF):]
            out.append(f"if {cond}:")
        elif line == _ENDIF:
            cond = None
        elif not line.startswith(_MARK):
            out.append(("    " if cond is not None else "") + line)
    return out


def outline(lines: list[str], prefix: str, inline: bool | None, after: list[str], external: set[str],
            min_len: int = 500) -> tuple[list[str], list[str]]:
    """Cut a straight-line statement list into ``@wp.func`` chunks of at least ``min_len`` statements.

    Clang compiles one huge function superlinearly: the humanoid step's adjoint as one function took two
    minutes at -O1, as seven non-inlined functions 16 s at -O2 (and ran faster than with 20). Each chunk
    takes the values it reads as arguments and returns the values read later (``after``: the statements
    that follow, e.g. array stores; ``external``: kernel variables and arguments defined before). A
    :func:`gate` region gets chunks of its own, called under its ``if``; its statements that reassign a
    name defined before the region stay in the kernel, after the calls. Returns (function sources, kernel
    statements).
    """
    chunks: list[list[str]] = [[]]
    region: list[str | None] = [None]  # the condition of each chunk's gate region
    phis: dict[int, list[str]] = {}  # last chunk of a region -> its reassignments
    defined: set[str] = set()
    for line in lines:
        if line.startswith(_IF) or line == _ENDIF:
            if chunks[-1]:
                chunks.append([])
                region.append(None)
            region[-1] = line[len(_IF):] if line.startswith(_IF) else None
            continue
        if line.startswith(_MARK):
            if len(chunks[-1]) >= min_len:
                chunks.append([])
                region.append(region[-1])
            continue
        lhs = line.split(" = ", 1)[0]
        if region[-1] is not None and lhs in defined:
            phis.setdefault(len(chunks) - 1, []).append(line)
            continue
        defined.add(lhs)
        chunks[-1].append(line)
    parsed = [[(lhs, _IDENT.findall(rhs)) for lhs, rhs in (line.split(" = ", 1) for line in chunk)] for chunk in chunks]
    last_use: dict[str, float] = {}
    for c, stmts in enumerate(parsed):
        for _, uses in stmts:
            for u in uses:
                last_use[u] = c
        for line in phis.get(c, ()):
            for u in _IDENT.findall(line.split(" = ", 1)[1]):
                last_use[u] = c + 0.5
    for line in after:
        for u in _IDENT.findall(line.split(" = ", 1)[1]):
            last_use[u] = len(parsed)
    hint = "" if inline is None else f"(inline={inline})"
    funcs, body = [], []
    for c, (chunk, stmts) in enumerate(zip(chunks, parsed)):
        pad = "" if region[c] is None else "    "
        if region[c] is not None and (c == 0 or region[c - 1] is None):
            body.append(f"if {region[c]}:")
        own = {lhs for lhs, _ in stmts}
        ins: list[str] = []
        for _, uses in stmts:
            for u in uses:
                if u not in own and u not in ins and (u in defined or u in external):
                    ins.append(u)
        outs = [lhs for lhs, _ in stmts if last_use.get(lhs, -1) > c]
        if outs:
            name = f"{prefix}{c}"
            args = ", ".join(f"{a}: S" for a in ins)
            funcs.append(f"@wp.func{hint}\ndef {name}({args}):\n" + indent(chunk, 1)
                         + f"\n    return {', '.join(outs)}\n")
            body.append(f"{pad}{', '.join(outs)} = {name}({', '.join(ins)})")
        body += [pad + line for line in phis.get(c, ())]
    return funcs, body


def indent(lines: list[str], depth: int) -> str:
    pad = "    " * depth
    return "\n".join(pad + line for line in lines)


def unmarked(lines: list[str]) -> list[str]:
    """The statements without the outlining marks."""
    return [x for x in lines if not x.startswith(_MARK)]
