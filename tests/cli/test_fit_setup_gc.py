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


def test_a_fit_whose_export_is_a_helpers_never_imports_dynamo(tmp_path, cartpole, record):
    """The fits' optimiser (:class:`wresdyn.learn.adam.Adam`) does not import torch._dynamo as torch.optim's does: a
    fit with its evaluation whose export runs in a helper process (``torch.export`` is the one user of it left) never
    imports it, and no set-up imports it for the fit."""
    import subprocess
    import sys

    from wresdyn.data.mismatch import Mismatch

    data = record(cartpole, Mismatch(), {"train": 2, "validation": 1, "heldout": 1, "ood": 1}, 0.4)
    data.gains = cartpole.gains_record()
    data.save(tmp_path / "cart.npz")
    code = (
        "import os, sys\n"
        "os.environ['WRESDYN_FIT_HELPERS'] = '1'\n"
        "from wresdyn.cli import main\n"
        f"code = main(['fit', {str(tmp_path / 'cart.npz')!r}, '--out', {str(tmp_path / 'run')!r}, '--iterations', '2',"
        " '--identify.iterations', '2', '--eval', '--quiet'])\n"
        "sys.exit(code or (3 if 'torch._dynamo' in sys.modules else 0))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "run" / "policy.pt").is_file()  # written by the helper, which imported it
