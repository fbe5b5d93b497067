"""One step cut into a chain of small kernels for the adjoint, so that NVRTC compiles pieces in parallel.

NVRTC compiles a kernel's forward and adjoint as one function, superlinearly in its length: the humanoid's whole
step with an adjoint is 76 CPU-seconds for sm_90 (``benchmarks/results/compile/cuda_probe_cpu.txt``), the first
GPU run's wait. Cut at the step's marks into kernels of about ``min_len`` statements, each piece compiles in
seconds and the pieces compile side by side (each kernel is its own Warp module). The values a later piece reads
travel through a per-world scratch array, written once per step (single assignment, so Warp's adjoint of every
piece reads the values of the step being differentiated):

- forward: the solver keeps running the whole step as one kernel (no scratch traffic);
- adjoint of one step: pieces ``0 .. m-2`` forward (they write the scratch, never the outputs), the scratch's
  gradient zeroed, then the adjoints of pieces ``m-1 .. 0``. Piece ``m-1`` writes the new state.

A :func:`~.emit.gate` region (the friction solve) is cut into pieces of its own that run under its condition;
its reassignments of earlier names become new names (``<name>_g``, the region's result where the condition holds,
the earlier value elsewhere), so that no scratch slot is written twice.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from .emit import _ENDIF, _IDENT, _IF, _MARK

__all__ = ["Piece", "split_lanes", "split_pieces"]

_SLOT = re.compile(r"scratch\[(\d+), w\]")


@dataclass
class Piece:
    """One kernel of the chain: its statements and the scratch slots it reads and writes."""

    lines: list[str] = field(default_factory=list)
    cond: str | None = None
    """The gate condition the piece runs under (None: always)."""
    phis: list[tuple[str, str, str]] = field(default_factory=list)
    """(new name, value where ``cond`` holds, value elsewhere) defined at the end of the piece."""


def _rename(line: str, names: dict[str, str]) -> str:
    if not names:
        return line
    return _IDENT.sub(lambda m: names.get(m.group(0), m.group(0)), line)


def _cut(compute: list[str], stores: list[str], min_len: int) -> list[Piece]:
    """The statements in pieces cut at marks (at least ``min_len`` statements each) and at gate boundaries; the
    stores go in a last piece outside any gate."""
    pieces = [Piece()]
    defined: set[str] = set()
    renamed: dict[str, str] = {}
    for line in compute:
        if line.startswith(_IF) or line == _ENDIF:
            if pieces[-1].lines or pieces[-1].phis:
                pieces.append(Piece())
            pieces[-1].cond = line[len(_IF):] if line.startswith(_IF) else None
            continue
        if line.startswith(_MARK):
            if len(pieces[-1].lines) >= min_len:
                pieces.append(Piece(cond=pieces[-1].cond))
            continue
        lhs, rhs = line.split(" = ", 1)
        rhs = _rename(rhs, renamed)
        if pieces[-1].cond is not None and lhs in defined:  # the region hands on a new value of an earlier name
            new = f"{lhs}_g"
            pieces[-1].phis.append((new, rhs, renamed.get(lhs, lhs)))
            renamed[lhs] = new
            continue
        defined.add(lhs)
        pieces[-1].lines.append(f"{lhs} = {rhs}")
    if pieces[-1].cond is not None:
        pieces.append(Piece())
    pieces[-1].lines += [_rename(s, renamed) for s in stores]
    return [p for p in pieces if p.lines or p.phis]


def split_pieces(prologue: list[str], compute: list[str], stores: list[str], min_len: int
                 ) -> tuple[list[list[str]], int]:
    """Kernel bodies of the chain for one step.

    Args:
        prologue: Loads and definitions any piece may need (parameter and state loads, gravity, ``fric_on``):
            each piece repeats the ones it uses, and what they use.
        compute: The step's statements, with :meth:`~.emit.Emitter.mark` and :func:`~.emit.gate` lines.
        stores: The array stores of the new state (``joint_q_out[...] = name``).
        min_len: Statements a piece reaches before it is cut at the next mark.

    Returns:
        (the body statements of each piece, reading and writing ``scratch[slot, w]``; the number of slots).
    """
    pre = [line.split(" = ", 1) for line in prologue]
    pieces = _cut(compute, stores, min_len)
    slots: dict[str, int] = {}
    plans = []  # per piece: (names it uses, scratch names it reads, names it defines in order)
    before: set[str] = set()  # names the earlier pieces define
    for p in pieces:
        texts = [line.split(" = ", 1)[1] for line in p.lines] + [f"{rhs} {old}" for _, rhs, old in p.phis]
        uses = list(dict.fromkeys(x for t in texts + [p.cond or ""] for x in _IDENT.findall(t)))
        own = [line.split(" = ", 1)[0] for line in p.lines if not _is_store(line)] + [new for new, _, _ in p.phis]
        reads = [x for x in uses if x in before and x not in own]
        for x in reads:
            slots.setdefault(x, len(slots))
        plans.append((uses, reads, own))
        before.update(own)
    bodies = []
    for p, (uses, reads, own) in zip(pieces, plans):
        need = set(uses)
        body_pre = []
        for lhs, rhs in reversed(pre):  # the prologue's closure over what this piece uses
            if lhs in need:
                need |= set(_IDENT.findall(rhs))
                body_pre.append(f"{lhs} = {rhs}")
        body_pre.reverse()
        loads = [f"{x} = scratch[{slots[x]}, w]" for x in reads]
        writes = [f"scratch[{slots[x]}, w] = {x}" for x in own if x in slots]
        if p.cond is None:
            bodies.append(body_pre + loads + p.lines + writes)
            continue
        inner = p.lines + [f"{new} = {rhs}" for new, rhs, _ in p.phis] + writes
        other = [f"scratch[{slots[new]}, w] = {old}" for new, _, old in p.phis if new in slots]
        bodies.append(body_pre + loads + [f"if {p.cond}:", *_indented(inner)]
                      + (["else:", *_indented(other)] if other else []))
    return bodies, len(slots)


def split_lanes(parts: list[tuple[list[str], list[str], list[str], list[str]]], min_len: int
                ) -> tuple[list[list[str]], int]:
    """Kernel bodies of the chain for one step run as lanes (:func:`~.codegen._lanes`: one thread per world and branch,
    ``parts`` each lane's (parameter loads, state loads, statements, stores)). Each lane's step is cut on its own by
    :func:`split_pieces`, its scratch slots placed after the earlier lanes', and the lanes' pieces aligned at the end,
    so that the last kernel writes every lane's new state (the chain's contract): kernel ``c`` of ``m`` runs, under
    ``if lane == l``, lane ``l``'s piece ``c - m + m_l``. Returns (the body statements of each kernel, the slots)."""
    cut = [split_pieces(params + loads, compute, stores, min_len) for params, loads, compute, stores in parts]
    m = max(len(lane_bodies) for lane_bodies, _ in cut)
    bodies: list[list[str]] = [[] for _ in range(m)]
    offset = 0
    for lane, (lane_bodies, slots) in enumerate(cut):
        for j, body in enumerate(lane_bodies):
            moved = [_SLOT.sub(lambda x: f"scratch[{int(x.group(1)) + offset}, w]", line) for line in body]
            bodies[m - len(lane_bodies) + j] += [f"if lane == {lane}:", *_indented(moved)]
        offset += slots
    return bodies, offset


def _indented(lines: list[str]) -> list[str]:
    return ["    " + line for line in lines]


def _is_store(line: str) -> bool:
    return "[" in line.split(" = ", 1)[0]
