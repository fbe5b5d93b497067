"""Figures: Fig. 3-style replays (real vs PD only vs PD + residual) and Fig. 4-style learning curves."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..data.dataset import fitted_mask

__all__ = ["plot_fig3", "save_figure", "learning_curves", "plot_learning_curves"]


def plot_fig3(robot, traj, runs: dict, path: str | Path, rate_hz: float, n_joints: int = 6, title: str = "",
              weights=None) -> Path:
    """Fig. 3-style plot of the first trajectory of ``runs`` (:func:`~wresdyn.evaluation.open_loop.evaluate_split`):
    real (red), PD only (green), PD + residual (blue), for the ``n_joints`` joints with the largest PD-only error
    among those with ``weights > 0`` (per-joint weights (n_dof,), e.g. ``Dataset.fit_weights()``; ``None``: all)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    q_pd = runs["pd"].q[0]
    q_res = runs["residual"].q[0] if "residual" in runs else None
    err = np.sqrt(np.nanmean((q_pd - traj.q) ** 2, axis=0))
    fitted = np.flatnonzero(fitted_mask(weights, len(err)))
    joints = fitted[np.argsort(-err[fitted], kind="stable")][:n_joints]
    n_joints = len(joints)
    t = np.arange(len(traj.q)) / rate_hz
    cols = 2 if n_joints > 1 else 1
    rows = int(np.ceil(n_joints / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(5.5 * cols, 2.2 * rows), sharex=True, squeeze=False)
    for ax, j in zip(axes.ravel(), joints):
        ax.plot(t, traj.q[:, j], color="red", lw=1.6, label="real")
        ax.plot(t, q_pd[:, j], color="green", lw=1.0, label="without residual")
        if q_res is not None:
            ax.plot(t, q_res[:, j], color="blue", lw=1.0, ls="--", label="with residual")
        ax.set_title(robot.joint_names[j], fontsize=9)
        ax.set_ylabel("q [rad]")
    for ax in axes[-1]:
        ax.set_xlabel("t [s]")
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(title or traj.name)
    fig.tight_layout()
    return save_figure(fig, path)


def save_figure(fig, path: str | Path, dpi: int = 110) -> Path:
    """Write a matplotlib figure (parent folders created) and close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path


def learning_curves(run_dir: str | Path, tags=("Reward/mimic", "Train/mean_reward", "Error/mean_abs_dq")) -> dict:
    """Scalars logged to tensorboard in ``run_dir``: tag -> (iterations (k,), values (k,)); later files win."""
    curves: dict[str, dict[int, float]] = {}
    files = sorted(Path(run_dir).glob("events.out.tfevents.*"), key=lambda p: p.stat().st_mtime)
    if files:  # tensorboard's reader takes a few tenths of a second to import; a gradient fit logs no events
        from tensorboard.backend.event_processing.event_accumulator import EventAccumulator
    for f in files:
        acc = EventAccumulator(str(f), size_guidance={"scalars": 0})
        acc.Reload()
        for tag in tags:
            if tag in acc.Tags().get("scalars", []):
                curves.setdefault(tag, {}).update({e.step: e.value for e in acc.Scalars(tag)})
    return {k: (np.array(sorted(v)), np.array([v[i] for i in sorted(v)])) for k, v in curves.items()}


def plot_learning_curves(runs: dict[str, str | Path], path: str | Path) -> Path:
    """Fig. 4-style comparison: mean mimic reward and training tracking error per iteration, one line per run."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(10, 3.4))
    for label, run in runs.items():
        c = learning_curves(run)
        for ax, tag in zip(axes, ("Reward/mimic", "Error/mean_abs_dq")):
            if tag in c:
                ax.plot(*c[tag], label=label)
    axes[0].set_ylabel("joint mimic reward per step")
    axes[1].set_ylabel("training mean |Δq| [rad]")
    for ax in axes:
        ax.set_xlabel("PPO iteration")
        if ax.lines:  # runs without PPO logs (the gradient fit) draw nothing
            ax.legend()
    fig.tight_layout()
    return save_figure(fig, path)
