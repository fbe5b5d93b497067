"""The end of ``wresdyn fit --eval`` that needs no simulator, in helper processes: the exported residual
(``policy.pt`` and ``policy.onnx``) and the figures.

A helper starts after the fit's set-up and imports ``torch.export``, torch's ONNX exporter and matplotlib (and warms
them up) while the fit runs. At the end the fit hands it jobs (a module-level function and its arguments, pickled
and framed on its standard input): the residual's two files, exported from a copy of the trained module (the same
files as this process would write: one export, then its ONNX twin), while the fit evaluates the module in memory;
then the evaluation's figures, drawn from light copies of what they plot. The fit waits for the helpers before it
returns; a job that failed fails the command with its error's last line. Each file a job writes is written under a
temporary name beside it and renamed into place, so a failed or stopped job leaves no half-written file.
"""

from __future__ import annotations

import os
import pickle
import queue
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

from . import UserError

__all__ = ["Helper", "write_into_place", "main"]

_HEAD = 8
"""Bytes of a job's frame header on the helper's standard input: the length of its pickle."""


class Helper:
    """``processes`` helper processes: ``submit(targets, function, *args, **kwargs)`` queues the job that writes the
    files ``targets`` (:func:`write_into_place`), ``close()`` waits for all of them. Several let the figures drawn
    after the replays be drawn side by side: then the first job (the fit's export, the longest) has the first helper
    to itself and the later ones take the others in turn; one helper runs every job in order."""

    def __init__(self, processes: int = 1):
        # what a helper prints goes to a file, read at the end: an error's last line becomes the command's, anything
        # else is passed on; a pipe could fill and stop the helper while the fit is not reading it
        self._errors = [tempfile.TemporaryFile() for _ in range(max(1, processes))]
        self._procs = [subprocess.Popen([sys.executable, "-m", "wresdyn.cli.fit_tail"], stdin=subprocess.PIPE,
                                        stderr=err) for err in self._errors]
        self._submitted = 0
        self.processes = len(self._procs)
        self._targets: list[Path] = []
        self._closed = False

    def submit(self, targets, function, *args, **kwargs) -> None:
        """Queue ``write_into_place(targets, function, *args, **kwargs)``: ``function`` writes the file ``targets``
        (or each of a tuple of them), named in ``args`` or ``kwargs``."""
        targets = tuple(map(Path, targets)) if isinstance(targets, (tuple, list)) else (Path(targets),)
        self._targets += targets
        frame = pickle.dumps((write_into_place, (targets, function, *args), kwargs))
        n = len(self._procs)
        proc = self._procs[0 if n == 1 or not self._submitted else 1 + (self._submitted - 1) % (n - 1)]
        self._submitted += 1
        try:
            proc.stdin.write(len(frame).to_bytes(_HEAD, "little") + frame)
            proc.stdin.flush()
        except BrokenPipeError:  # the helper failed on an earlier job: close() says so
            pass

    def close(self) -> None:
        """Wait for every job submitted. Raises :class:`~wresdyn.cli.UserError` (one line: the failed job's error)
        when one failed. Once: later calls return at once."""
        if self._closed:
            return
        self._closed = True
        for proc in self._procs:
            try:
                proc.stdin.close()
            except BrokenPipeError:
                pass
        codes = [proc.wait() for proc in self._procs]
        said = []
        for err in self._errors:
            err.seek(0)
            said.append(err.read().decode(errors="replace"))
            err.close()
        failed = [(code, text) for code, text in zip(codes, said) if code]
        for code, text in zip(codes, said):
            if not code and text:
                sys.stderr.write(text)
        if failed:
            self._remove_parts()
            code, text = failed[0]
            lines = [ln for ln in text.splitlines() if ln.strip()]
            raise UserError(f"the fit's helper process (policy.pt, policy.onnx, figures) failed (exit status {code})"
                            + (f": {lines[-1].strip()}" if lines else ""))

    def __enter__(self) -> Helper:
        return self

    def __exit__(self, kind, error, trace) -> None:
        if kind is None:
            self.close()
            return
        if self._closed:
            return
        self._closed = True
        for proc in self._procs:  # the command failed: what the helpers had left to write is not wanted
            proc.kill()
            proc.wait()
        for err in self._errors:
            err.close()
        self._remove_parts()

    def _remove_parts(self) -> None:
        for target in self._targets:
            part = _part(target)
            part.unlink(missing_ok=True)
            part.with_name(part.name + ".tmp").unlink(missing_ok=True)  # save_program's own name for a part


def _part(target: Path) -> Path:
    """The name ``target`` is written under until it is complete: hidden, beside it, with its suffix (which says
    matplotlib's format)."""
    return target.with_name(f".{target.stem}.part{target.suffix}")


def write_into_place(targets, function, *args, **kwargs) -> None:
    """``function(*args, **kwargs)`` with each path of ``targets`` in ``args`` and ``kwargs`` replaced by
    :func:`_part`'s name, then those files renamed into place once all are written; removed when ``function``
    fails."""
    parts = {Path(t): _part(Path(t)) for t in targets}

    def swap(x):
        return type(x)(parts[Path(x)]) if isinstance(x, (str, Path)) and Path(x) in parts else x

    try:
        function(*map(swap, args), **{k: swap(v) for k, v in kwargs.items()})
        for target, part in parts.items():
            os.replace(part, target)
    except BaseException:
        for part in parts.values():
            part.unlink(missing_ok=True)
        raise


def main() -> int:
    """The helper: import and set up what the jobs need, then run each job read from standard input until it
    closes. A failed job ends the process with its error's last line on standard error and status 1."""
    # the jobs are read as they come, from the start, so that the fit's writes (a figure's job holds whole
    # trajectories: megabytes, far more than a pipe's buffer) never wait for this process's set-up or the job before
    jobs = queue.SimpleQueue()
    threading.Thread(target=_read, args=(sys.stdin.buffer, jobs), daemon=True).start()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot  # noqa: F401
    import torch

    torch.set_num_threads(1)  # the jobs are small; the fit's cores stay its own
    import torch.onnx._internal.exporter._core  # noqa: F401  (the exporter and onnxscript: most of its first call)

    from ..evaluation import plots  # noqa: F401
    from ..learn import residual  # noqa: F401

    _warm_up()
    while (frame := jobs.get()) is not None:
        try:
            if isinstance(frame, BaseException):  # what was sent could not be read
                raise frame
            function, args, kwargs = pickle.loads(frame)
            function(*args, **kwargs)
        except Exception as e:  # noqa: BLE001  (any job's error ends the helper, said in one line)
            print(f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}", file=sys.stderr, flush=True)
            return 1
    return 0


def _warm_up() -> None:
    """A process's first ``torch.export``, first ONNX export and first figure set up what every later one reuses (on
    the CPU the first ONNX export took 3.6 s, the next 1.2-1.6 s): all done here on throwaway ones, before the fit
    needs them. The files the jobs write are the same bytes (``tests/cli/test_fit_tail.py``)."""
    import io

    import matplotlib.pyplot as plt
    import torch

    from ..learn.network_file import export_onnx

    module, obs = torch.nn.Linear(2, 1).eval(), torch.zeros(2, 2)
    program = torch.export.export(module, (obs,), dynamic_shapes={"input": {0: torch.export.Dim("batch", min=1)}})
    with tempfile.TemporaryDirectory() as folder:
        export_onnx(program, Path(folder) / "warm_up.onnx", ["obs"], ["residual"])
    fig, ax = plt.subplots()
    ax.plot([0.0, 1.0], label="warm-up")
    ax.legend()
    fig.tight_layout()
    fig.savefig(io.BytesIO(), format="png")
    plt.close(fig)


def _read(stdin, jobs) -> None:
    """Put each job's frame of ``stdin`` (its pickle, unread: unpickling imports, which are the main thread's) on
    ``jobs``, then ``None`` when it closes (the error, where a frame is cut short)."""
    while True:
        head = stdin.read(_HEAD)
        if not head:
            jobs.put(None)
            return
        size = int.from_bytes(head, "little")
        frame = stdin.read(size)
        if len(head) < _HEAD or len(frame) < size:
            jobs.put(EOFError("a job cut short"))
            return
        jobs.put(frame)


if __name__ == "__main__":
    sys.exit(main())
