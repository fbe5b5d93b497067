"""How much cyclic garbage ``wresdyn fit``'s set-up leaves for :func:`wresdyn.cli.fit.long_lived` to freeze.

    python setup_garbage.py      (from the repository root, PYTHONPATH naming the tree)

Runs a tiny fit's set-up (data, kernels, the Newton check) with the collector off, as ``long_lived`` does, then, instead
of freezing, counts the objects a full collection finds unreachable (those ``long_lived`` freezes with the live ones)
and the objects still tracked, and stops.
"""
import contextlib
import gc

import wresdyn.cli
import wresdyn.cli.fit as fit_command


@contextlib.contextmanager
def counted():
    gc.disable()
    try:
        yield
    finally:
        n = gc.collect()
        print(f"set-up left {n} unreachable objects (what long_lived freezes with the live ones); tracked now "
              f"{len(gc.get_objects())}", flush=True)
        raise SystemExit(0)


fit_command.long_lived = counted
wresdyn.cli.main(["fit", "data/dataset.npz", "--device", "cpu", "--out", "/tmp/startup_cpu_runs/garbage",
                  "--iterations", "1", "--identify.iterations", "1", "--windows", "4", "--quiet"])
