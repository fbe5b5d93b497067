"""The frequency content of excitation commands: their power spectrum (:func:`command_spectrum`), the share of
each joint's energy in a band (:func:`band_fraction`) and the plot ``wresdyn collect`` writes (:func:`plot_spectrum`),
to check that an excitation spans the broad band the paper asks of it (Sec. II-A)."""

from __future__ import annotations

import numpy as np

__all__ = ["command_spectrum", "band_fraction", "plot_spectrum"]


def command_spectrum(q_cmd: list[np.ndarray] | np.ndarray, rate_hz: float) -> tuple[np.ndarray, np.ndarray]:
    """Power spectral density of the commands, Hann-windowed periodogram after removing each joint's mean,
    averaged over trajectories (all of the same length); returns ``(f [Hz], psd [rad^2/Hz])``, psd of shape
    (n_freq, n_dof)."""
    from scipy.signal import periodogram

    q = np.asarray(q_cmd, dtype=np.float64)
    q = q[None] if q.ndim == 2 else q
    f, p = periodogram(q, fs=rate_hz, window="hann", detrend="constant", axis=1)
    return f, p.mean(axis=0)


def band_fraction(f: np.ndarray, psd: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Fraction of each joint's command energy in ``lo <= f < hi`` [Hz], shape (n_dof,)."""
    total = psd.sum(axis=0)
    band = psd[(f >= lo) & (f < hi)].sum(axis=0)
    return band / np.where(total > 0, total, 1.0)


def plot_spectrum(groups: dict[str, list[np.ndarray]], rate_hz: float, path, joint_names: list[str]) -> None:
    """Save a log-log plot of the command PSD (mean over joints) per group of trajectories, with the per-joint
    spread shaded, to ``path`` (PNG)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4.2), constrained_layout=True)
    f_min = rate_hz / 2
    for name, qs in groups.items():
        if not qs:
            continue
        f, p = command_spectrum(qs, rate_hz)
        keep = (f > 0) & (p.mean(axis=1) > 0)  # log axes: a held (constant) command has no power to draw
        if not keep.any():
            continue
        f_min = min(f_min, f[keep][0])
        line, = ax.loglog(f[keep], p[keep].mean(axis=1), label=f"{name} (mean of {len(joint_names)} joints)")
        ax.fill_between(f[keep], np.quantile(p[keep], 0.1, axis=1), np.quantile(p[keep], 0.9, axis=1),
                        color=line.get_color(), alpha=0.15, linewidth=0)
    f_max = min(50.0, rate_hz / 2)
    for x in (0.5, 2.0):  # the bands the frequency-content check compares
        if not f_min <= x <= f_max:  # a short recording starts above them; a label outside would squash the axes
            continue
        ax.axvline(x, color="0.6", linestyle=":", linewidth=1)
        ax.text(x, 1.0, f" {x:g} Hz", transform=ax.get_xaxis_transform(), va="top", fontsize=8, color="0.4")
    ax.set_xlim(f_min, f_max)
    ax.set_xlabel("frequency [Hz]")
    ax.set_ylabel("command PSD [rad²/Hz]")
    ax.set_title("Excitation command spectrum (shaded: 10-90 % of joints)")
    ax.legend(loc="lower left", fontsize=8)
    fig.savefig(path, dpi=120)
    plt.close(fig)
