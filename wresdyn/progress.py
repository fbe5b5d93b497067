"""Progress of long loops (fits, identification, PPO, recordings) you can read: a bar on a terminal, plain lines
elsewhere.

A command makes one :class:`Log` and hands it to the library as its ``log`` printer. Its lines go to the terminal
(unless ``quiet``) and, always, to a log file in the run folder. A loop asks :func:`bar` for a progress bar over
its iterations: on a terminal a tqdm bar with the elapsed and the remaining time, the lines printed above it;
when the output is not a terminal (a pipe, a batch job's file) a plain line every ``every`` seconds instead, with
the same figures; with a plain ``print`` (or any other callable) as the printer, no bar at all, so library callers
and tests see only their lines.
"""

from __future__ import annotations

import contextlib
import sys
import time
from pathlib import Path

__all__ = ["Log", "bar", "into_file"]


class Log:
    """A command's printer: ``log(line)`` prints ``line`` (unless ``quiet``) and appends it to ``path``.

    Args:
        path: Log file, appended to; ``None`` for none. Lines wait in memory until its folder exists: the command
            makes the run folder once its inputs are checked, so a refused run leaves no folder behind.
        quiet: Print nothing on the terminal; the file still gets every line.
        stream: Where lines and the bar go (default ``sys.stdout``).
        every: Period of the plain progress lines when ``stream`` is not a terminal [s].
    """

    def __init__(self, path=None, quiet: bool = False, stream=None, every: float = 30.0) -> None:
        self.path = None if path is None else Path(path)
        self.quiet, self.every = bool(quiet), float(every)
        self.stream = stream if stream is not None else sys.stdout
        self.active = None  # the bar being drawn, if any: lines go above it
        self._waiting: list[str] = []  # lines for the file, before its folder exists

    def __call__(self, line: str) -> None:
        if self.path is not None:
            self._waiting.append(line)
            if self.path.parent.is_dir():
                with open(self.path, "a") as f:
                    f.write("".join(f"{ln}\n" for ln in self._waiting))
                self._waiting.clear()
        if self.quiet:
            return
        if self.active is not None and self.active.tqdm is not None:
            self.active.tqdm.write(line, file=self.stream)
        else:
            print(line, file=self.stream, flush=True)

    def terminal(self) -> bool:
        """Whether the stream is an interactive terminal (a bar can redraw itself there)."""
        return bool(getattr(self.stream, "isatty", lambda: False)())


class _Bar:
    """Iterations ``initial..total`` of a loop: ``update(n, note)`` after each; the note (e.g. the loss) shows on the
    bar or the plain line."""

    def __init__(self, log, total: int, desc: str, initial: int = 0) -> None:
        self.log, self.total, self.desc = log, int(total), desc
        self.n = self.start = int(initial)
        self.t0 = self.last = time.monotonic()
        self.note = ""
        self.tqdm = None
        if isinstance(log, Log) and not log.quiet and log.terminal():
            from tqdm import tqdm

            self.tqdm = tqdm(total=self.total, initial=self.n, desc=desc, file=log.stream, dynamic_ncols=True,
                             bar_format="{desc}: {n_fmt}/{total_fmt} |{bar}| {elapsed} elapsed, {remaining} left"
                                        "{postfix}")

    def update(self, n: int = 1, note: str | None = None) -> None:
        self.n += n
        if note is not None:
            self.note = note
        if self.tqdm is not None:
            if note is not None:
                self.tqdm.set_postfix_str(note, refresh=False)
            self.tqdm.update(n)
            return
        now = time.monotonic()
        if isinstance(self.log, Log) and not self.log.quiet and (now - self.last >= self.log.every
                                                                  or self.n >= self.total):
            self.last = now
            print(self.line(now), file=self.log.stream, flush=True)

    def line(self, now: float | None = None) -> str:
        """The plain progress line: iterations done, elapsed and remaining time (at the rate so far)."""
        elapsed = (now or time.monotonic()) - self.t0
        done = self.n - self.start
        left = (self.total - self.n) * elapsed / done if done > 0 else float("nan")
        pct = 100.0 * self.n / self.total if self.total else 100.0
        return (f"{self.desc}: {self.n}/{self.total} ({pct:.0f} %), {_clock(elapsed)} elapsed, "
                f"{_clock(left)} left" + (f", {self.note}" if self.note else ""))

    def __enter__(self):
        if isinstance(self.log, Log):
            self.log.active = self
        return self

    def __exit__(self, *exc) -> None:
        if self.tqdm is not None:
            self.tqdm.close()
        if isinstance(self.log, Log):
            self.log.active = None


def bar(log, total: int, desc: str, initial: int = 0) -> _Bar:
    """A progress bar over iterations ``initial..total`` of a loop that prints through ``log`` (a context manager:
    ``with bar(log, n, "fit") as b: ... b.update(1)``); drawn only when ``log`` is a :class:`Log`."""
    return _Bar(log, total, desc, initial)


@contextlib.contextmanager
def into_file(path):
    """Within the block, what a library prints on stdout (rsl-rl's networks and per-iteration tables) is appended to
    ``path`` instead of the terminal, where it would bury the bar; ``None`` leaves stdout as it is (torchrun ranks
    other than 0, which have no run folder)."""
    if path is None:
        yield
        return
    with open(path, "a") as f, contextlib.redirect_stdout(f):
        yield


def _clock(seconds: float) -> str:
    """``h:mm:ss`` or ``m:ss``; ``?`` before the rate is known."""
    if not seconds == seconds or seconds == float("inf"):
        return "?"
    s = int(round(seconds))
    h, m = divmod(s // 60, 60)
    return f"{h}:{m:02d}:{s % 60:02d}" if h else f"{m}:{s % 60:02d}"
