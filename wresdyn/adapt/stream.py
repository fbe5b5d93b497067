"""The robot's stream of samples as :class:`~wresdyn.adapt.adapter.Adapter` takes it: replayed from a recorded
dataset, or read live from a text pipe.

Line format (one sample per line, whitespace- or comma-separated numbers, SI units)::

    t q1 .. qn qd1 .. qdn qcmd1 .. qcmdn

``t`` [s] strictly increasing, ``q`` [rad], ``qd`` [rad/s], ``qcmd`` [rad] (the command held from ``t`` until the
next sample), the joints in the robot's order; empty lines and lines starting with ``#`` are skipped. A jump in time
of more than 1.5 sample periods starts a new segment (the robot stopped recording, or a new log).
"""

from __future__ import annotations

import re
from typing import IO, Iterator

import numpy as np

from .adapter import StreamError

__all__ = ["Block", "dataset_blocks", "text_blocks", "SEGMENT_GAP"]

SEGMENT_GAP = 1.0
"""Time inserted between the trajectories of a replayed dataset [s] (each becomes a segment of its own)."""

Block = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]
"""Samples ``(t (T,) [s], q (T, n) [rad], qd (T, n) [rad/s], q_cmd (T, n) [rad])``."""

_SEP = re.compile(r"[,\s]+")


def dataset_blocks(dataset, splits=None) -> Iterator[Block]:
    """The trajectories of ``dataset`` (those of ``splits``, default all, in the file's order) one after the other,
    each shifted in time to start :data:`SEGMENT_GAP` after the previous one ends."""
    offset = 0.0
    for tr in dataset.trajectories:
        if splits and tr.split not in splits:
            continue
        t = tr.t - tr.t[0] + offset
        yield t, tr.q, tr.qd, tr.q_cmd
        offset = t[-1] + SEGMENT_GAP


def text_blocks(lines: IO[str], n_dof: int, where: str = "stdin", block: int = 1) -> Iterator[Block]:
    """Parse the line format (module docstring) from ``lines``; yield every ``block`` samples (1: each sample as it
    arrives, as a live stream needs). Raises :class:`~wresdyn.adapt.adapter.StreamError` naming the line for a line
    with the wrong count of numbers, a word that is not a number, a value that is not finite or a time that does not
    increase."""
    width = 1 + 3 * n_dof
    rows: list[np.ndarray] = []
    last = -np.inf
    for i, line in enumerate(lines, 1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        words = _SEP.split(text)
        if len(words) != width:
            raise StreamError(f"{where}:{i}: {len(words)} numbers, expected {width} (t, then q, qd, q_cmd of the "
                              f"robot's {n_dof} joints)")
        try:
            row = np.array([float(w) for w in words])
        except ValueError:
            raise StreamError(f"{where}:{i}: not a number in {text[:60]!r}") from None
        if not np.isfinite(row).all():
            raise StreamError(f"{where}:{i}: a value is not finite (t = {row[0]:.6g} s)")
        if row[0] <= last:
            raise StreamError(f"{where}:{i}: time {row[0]:.6g} s does not increase (after {last:.6g} s)")
        last = row[0]
        rows.append(row)
        if len(rows) >= block:
            yield _split(rows, n_dof)
            rows = []
    if rows:
        yield _split(rows, n_dof)


def _split(rows: list[np.ndarray], n: int) -> Block:
    a = np.stack(rows)
    return a[:, 0], a[:, 1:1 + n], a[:, 1 + n:1 + 2 * n], a[:, 1 + 2 * n:]
