"""The fit's set-up runs without the cyclic collector and freezes what it leaves alive
(:func:`wresdyn.cli.fit.long_lived`), its export and evaluation without the collector
(:func:`~wresdyn.cli.fit.without_collector`); the collector's state is restored even when the set-up fails."""

import gc

import pytest

from wresdyn.cli.fit import long_lived, without_collector


def test_the_set_up_runs_without_the_collector_and_its_objects_are_frozen():
    assert gc.isenabled()
    before = gc.get_freeze_count()
    try:
        with long_lived():
            assert not gc.isenabled()
            kept = [[i] for i in range(1000)]  # objects the set-up leaves alive
        assert gc.isenabled()
        assert gc.get_freeze_count() >= before + len(kept)
    finally:
        gc.unfreeze()  # the rest of the test process collects normally


def test_a_failed_set_up_gives_the_collector_back():
    try:
        with pytest.raises(RuntimeError):
            with long_lived():
                raise RuntimeError("no data")
        assert gc.isenabled()
    finally:
        gc.unfreeze()


def test_a_disabled_collector_stays_disabled():
    gc.disable()
    try:
        with long_lived():
            pass
        assert not gc.isenabled()
    finally:
        gc.enable()
        gc.unfreeze()


def test_the_last_part_runs_without_the_collector_and_freezes_nothing():
    before = gc.get_freeze_count()
    with without_collector():
        assert not gc.isenabled()
        kept = [[i] for i in range(100)]
    assert gc.isenabled() and gc.get_freeze_count() == before and kept


def test_the_optimisers_dynamo_import_is_part_of_the_frozen_set_up():
    """Every optimiser imports torch._dynamo (167,000 objects): the fit's set-up imports it, the collector off, before
    the data load (here made to stop the command)."""
    import subprocess
    import sys

    code = (
        "import gc, sys\n"
        "import wresdyn.data.loading as loading\n"
        "from wresdyn.cli.fit import Fit, run\n"
        "def stop(*a, **k):\n"
        "    raise SystemExit(0 if 'torch._dynamo' in sys.modules and not gc.isenabled() else 3)\n"
        "loading.load_data = stop\n"
        "assert 'torch._dynamo' not in sys.modules\n"
        "run(Fit(data='none.npz', quiet=True))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
