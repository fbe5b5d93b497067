"""The log clock of a command (:mod:`wresdyn.cli.clock`): seconds since the process started on each line and the
time of each loop's first finished iteration, only when ``WRESDYN_LOG_CLOCK`` asks for them."""

from __future__ import annotations

import io
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest

from wresdyn.cli.clock import CLOCK_ENV, ClockLog, clock_on, since_start
from wresdyn.paths import REPO
from wresdyn.progress import bar

STAMP = re.compile(r"^\[ *(\d+\.\d) s\] (.*)$")
FIRST = re.compile(r"^first iteration of (\w+) done at (\d+\.\d) s after the process started$")


def test_clock_counts_from_the_process_start_not_the_import():
    """A process that sleeps before importing the module reads at least the sleep (the start is the interpreter's,
    from /proc), and not much more (the interpreter's own start)."""
    if not Path("/proc/self/stat").exists():
        pytest.skip("the process start is read from Linux's /proc")
    code = f"import time; time.sleep(1.0); import sys; sys.path.insert(0, {str(REPO)!r}); "
    code += "from wresdyn.cli.clock import since_start; print(since_start())"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=120)
    age = float(out.stdout.split()[-1])
    # 1.0 s asleep, then the import of wresdyn.progress (no torch): well under 20 s on a loaded 2-core machine
    assert 1.0 <= age < 20.0, age


def test_clock_on_reads_the_variable():
    assert not clock_on({})
    assert not clock_on({CLOCK_ENV: ""}) and not clock_on({CLOCK_ENV: "0"})
    assert clock_on({CLOCK_ENV: "1"})


def _loop(log, n=3, name="identify"):
    with bar(log, n, name) as progress:
        for _ in range(n):
            progress.update(1, "loss 1")
            log("iter")


def test_stamped_lines_and_one_first_iteration_line_per_loop(tmp_path):
    log = ClockLog(tmp_path / "fit.log", stream=io.StringIO(), clock=True)
    before = since_start()
    log("start")
    _loop(log, name="identify")
    _loop(log, name="fit")
    after = since_start()
    lines = (tmp_path / "fit.log").read_text().splitlines()
    stamps = [STAMP.match(ln) for ln in lines]
    assert all(stamps), lines
    times = [float(m[1]) for m in stamps]
    # the stamps are the process clock, rounded to 0.1 s, and never go back
    assert before - 0.06 <= times[0] and times[-1] <= after + 0.06, (before, times, after)
    assert times == sorted(times)
    texts = [m[2] for m in stamps]
    firsts = [FIRST.match(t) for t in texts]
    assert [f[1] for f in firsts if f] == ["identify", "fit"], texts
    # the first-iteration line comes right after the loop's first update, before that iteration's own line
    assert texts == ["start", firsts[1][0], "iter", "iter", "iter", firsts[5][0], "iter", "iter", "iter"], texts
    assert float(firsts[1][2]) <= float(firsts[5][2])


def test_without_the_clock_the_log_is_unchanged(tmp_path):
    log = ClockLog(tmp_path / "fit.log", stream=io.StringIO(), clock=False)
    log("start")
    _loop(log)
    assert (tmp_path / "fit.log").read_text().splitlines() == ["start", "iter", "iter", "iter"]


def test_clock_defaults_to_the_environment(tmp_path, monkeypatch):
    monkeypatch.setenv(CLOCK_ENV, "1")
    assert ClockLog(None, stream=io.StringIO()).clock
    monkeypatch.delenv(CLOCK_ENV)
    assert not ClockLog(None, stream=io.StringIO()).clock


def test_the_clock_moves(tmp_path):
    log = ClockLog(tmp_path / "fit.log", stream=io.StringIO(), clock=True)
    log("a")
    time.sleep(0.3)
    log("b")
    a, b = (float(STAMP.match(ln)[1]) for ln in (tmp_path / "fit.log").read_text().splitlines())
    assert 0.2 <= b - a <= 5.0, (a, b)

