"""The dataset's Savitzky-Golay derivative (:mod:`wresdyn.data.savgol`) is SciPy's, bit for bit, without importing
``scipy.signal``."""

import subprocess
import sys

import numpy as np
import pytest
from scipy.signal import savgol_filter as scipy_savgol

from wresdyn.data.savgol import savgol_filter


@pytest.mark.parametrize("window, polyorder, deriv", [(5, 2, 1), (11, 2, 1), (21, 2, 1), (9, 3, 2), (7, 2, 0),
                                                      (5, 1, 2)])
@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_the_filter_is_scipys_bit_for_bit(window, polyorder, deriv, dtype):
    rng = np.random.default_rng(window * 10 + deriv)
    x = rng.standard_normal((300, 7)).cumsum(0).astype(dtype)
    ours = savgol_filter(x, window, polyorder, deriv=deriv, delta=0.002)
    theirs = scipy_savgol(x, window, polyorder, deriv=deriv, delta=0.002, axis=0, mode="interp")
    assert ours.dtype == theirs.dtype and ours.shape == theirs.shape
    assert ours.tobytes() == theirs.tobytes()


def test_one_dimensional_and_window_long_inputs():
    x = np.sin(np.linspace(0, 3, 11))
    for n in (11, 12):
        xs = np.resize(x, n)
        assert savgol_filter(xs, 11, 2, deriv=1).tobytes() == scipy_savgol(xs, 11, 2, deriv=1, mode="interp").tobytes()


def test_the_dataset_derivation_does_not_import_scipy_signal():
    code = ("import sys, numpy as np; from wresdyn.data.dataset import derive_qdd; "
            "derive_qdd(np.ones((50, 3)), 500.0); print('scipy.signal' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip() \
        == "False"
