"""Seconds since the process started, on a command's log lines: where a first run's time goes, read off its log.

With ``WRESDYN_LOG_CLOCK=1`` in the environment a command's :class:`ClockLog` prefixes every line with the seconds
since the Python process started (``[  12.3 s] ...``; the interpreter's start, so the imports of torch, Warp and
Newton count) and, when the first iteration of each of its loops (a :func:`wresdyn.progress.bar`) is done, logs
``first iteration of NAME done at X s after the process started``: the figure a first-run target is stated in.
Without the variable the log is unchanged (tests and docs quote its lines).
"""

from __future__ import annotations

import os
import time

from ..progress import Log

__all__ = ["ClockLog", "CLOCK_ENV", "clock_on", "since_start"]

CLOCK_ENV = "WRESDYN_LOG_CLOCK"
"""Environment variable that switches the clock on (any value but empty or ``0``)."""


def _process_age() -> float | None:
    """Seconds since this process started [s], from Linux's ``/proc`` (its start in clock ticks since boot against
    the uptime, both on the boot clock); ``None`` where there is no ``/proc``."""
    try:
        with open("/proc/self/stat") as f:
            stat = f.read()
        with open("/proc/uptime") as f:
            uptime = float(f.read().split()[0])
        # the command name (field 2) may hold spaces: the fields after its closing parenthesis, starttime the 20th
        started = int(stat[stat.rindex(")") + 2:].split()[19]) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None
    return max(uptime - started, 0.0)


_AGE = _process_age()
_START = time.monotonic() - (_AGE if _AGE is not None else 0.0)
"""The process's start on :func:`time.monotonic`'s clock (this module's import where ``/proc`` is missing)."""


def since_start() -> float:
    """Seconds since the process started [s] (since this module's import where ``/proc`` is missing)."""
    return time.monotonic() - _START


def clock_on(environ=None) -> bool:
    """Whether :data:`CLOCK_ENV` asks for the clock in ``environ`` (default ``os.environ``)."""
    value = (os.environ if environ is None else environ).get(CLOCK_ENV, "")
    return value not in ("", "0")


class ClockLog(Log):
    """A :class:`~wresdyn.progress.Log` that, when ``clock`` is on, stamps each line with :func:`since_start` and
    logs the time of each loop's first finished iteration (the loop's bar's first ``update``).

    Args:
        clock: Stamp the lines; default :func:`clock_on` of the environment.
        args, kwargs: :class:`~wresdyn.progress.Log`'s.
    """

    def __init__(self, *args, clock: bool | None = None, **kwargs) -> None:
        self.clock = clock_on() if clock is None else bool(clock)
        self._bar = None
        super().__init__(*args, **kwargs)

    def __call__(self, line: str) -> None:
        super().__call__(f"[{since_start():7.1f} s] {line}" if self.clock else line)

    @property
    def active(self):
        """The bar being drawn (:class:`~wresdyn.progress.Log`'s); a bar set here has its first update timed."""
        return self._bar

    @active.setter
    def active(self, bar) -> None:
        self._bar = bar
        if bar is None or not self.clock:
            return
        update = bar.update

        def first_update(n: int = 1, note: str | None = None) -> None:
            bar.update = update  # once: later iterations go straight to the bar
            update(n, note)
            self(f"first iteration of {bar.desc} done at {since_start():.1f} s after the process started")

        bar.update = first_update
