"""The Savitzky-Golay derivative a dataset derives its accelerations with, without importing :mod:`scipy.signal`.

``scipy.signal`` imports most of SciPy (stats, interpolate, optimize, spatial: 1.1-1.6 s on the development
machine) for a filter that needs only a least-squares solve and a convolution. :func:`savgol_filter` is
``scipy.signal.savgol_filter`` with ``mode="interp"`` (SciPy 1.17's algorithm, its operations in its order:
``tests/data/test_savgol.py`` checks it bit for bit against SciPy's), on NumPy arrays along ``axis`` 0, through
:func:`scipy.linalg.lstsq` and :func:`scipy.ndimage.convolve1d` only. Adapted from SciPy
(``scipy/signal/_savitzky_golay.py``), BSD-3-Clause, Copyright (c) 2001-2002 Enthought, Inc., 2003-2024 SciPy
Developers.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["savgol_coeffs", "savgol_filter"]


def savgol_coeffs(window_length: int, polyorder: int, deriv: int = 0, delta: float = 1.0) -> np.ndarray:
    """Convolution coefficients of the filter for an odd ``window_length`` (``scipy.signal.savgol_coeffs``, its
    window centred, ``use="conv"``), shape (window_length,)."""
    from scipy.linalg import lstsq

    if window_length % 2 != 1 or not 0 <= polyorder < window_length:
        raise ValueError("an odd window_length above polyorder is needed")
    if deriv > polyorder:
        return np.zeros(window_length)
    pos = window_length // 2
    x = np.flip(np.arange(-pos, window_length - pos, dtype=np.float64))
    a = x ** np.arange(polyorder + 1, dtype=np.float64).reshape(-1, 1)
    y = np.zeros(polyorder + 1, dtype=np.float64)
    y[deriv] = float(math.factorial(deriv)) / (delta ** deriv)
    return lstsq(a, y, cond=np.finfo(np.float64).eps * max(a.shape))[0]


def _polyfit(x: np.ndarray, y: np.ndarray, deg: int) -> np.ndarray:
    """Coefficients of the degree-``deg`` least-squares polynomial of each column of ``y`` (k, m) at ``x`` (k,),
    highest power first, (deg + 1, m): SciPy's column-scaled Vandermonde solve."""
    from scipy.linalg import lstsq

    lhs = x[:, None] ** np.flip(np.arange(deg + 1, dtype=x.dtype))[None, :]
    scale = np.sqrt(np.sum(lhs * lhs, axis=0))
    lhs /= scale
    c = lstsq(lhs, y, cond=x.shape[0] * np.finfo(x.dtype).eps)[0]
    return (c.T / scale).T


def _fit_edge(x, start: int, stop: int, interp_start: int, interp_stop: int, polyorder: int, deriv: int,
              delta: float, y: np.ndarray) -> None:
    """Fill ``y[interp_start:interp_stop]`` from the polynomial fitted to ``x[start:stop]`` (its ``deriv``-th
    derivative), in place."""
    edge = x[start:stop]
    p = _polyfit(np.arange(0, stop - start, dtype=x.dtype), edge.reshape(edge.shape[0], -1), polyorder)
    if deriv > 0:
        n = p.shape[0]
        if n <= deriv:
            p = np.zeros_like(p[:1])
        else:
            p = np.array(p[:-deriv], copy=True)
            for k in range(deriv):
                p *= np.arange(n - k - 1, deriv - k - 1, -1, dtype=p.dtype).reshape((n - deriv, 1))
    i = np.arange(interp_start - start, interp_stop - start, dtype=p.dtype).reshape(-1, 1)
    values = np.zeros_like(i)
    for j in range(p.shape[0]):
        values = values * i + p[j]
    y[interp_start:interp_stop] = (values / (delta ** deriv)).reshape((interp_stop - interp_start, *y.shape[1:]))


def savgol_filter(x: np.ndarray, window_length: int, polyorder: int, deriv: int = 0, delta: float = 1.0
                  ) -> np.ndarray:
    """``scipy.signal.savgol_filter(x, window_length, polyorder, deriv, delta, axis=0, mode="interp")``: the
    filtered ``x`` (float64 or float32, at least ``window_length`` samples along axis 0), same shape."""
    from scipy.ndimage import convolve1d

    x = np.asarray(x)
    if x.dtype != np.float64 and x.dtype != np.float32:
        x = x.astype(np.float64)
    if window_length > x.shape[0]:
        raise ValueError("window_length must not exceed the samples along axis 0")
    coeffs = savgol_coeffs(window_length, polyorder, deriv=deriv, delta=delta)
    y = convolve1d(x, coeffs, axis=0, mode="constant")
    half, n = window_length // 2, x.shape[0]
    _fit_edge(x, 0, window_length, 0, half, polyorder, deriv, delta, y)
    _fit_edge(x, n - window_length, n, n - half, n, polyorder, deriv, delta, y)
    return y
