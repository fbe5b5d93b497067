"""Open-loop evaluation of a residual: PD-only vs PD + residual vs the recording (paper Sec. III-A, Fig. 3).

Each trajectory of a split is replayed from its first recorded state for its whole length, driven only by
the recorded commands, once with PD alone and once with the residual in the loop (deterministic). The
headline number is the mean |Δq| = |q_sim − q_real| over all joints and samples [rad], ± its std.

:func:`rollout` and :func:`evaluate_split` take any residual ``policy(obs) -> residual`` (a torch module
mapping raw [q, q̇, q̈, q_cmd] (N, 4n) to N*m or rad, (N, n), with an optional ``reset()``), so a gradient
learner can reuse them. :func:`write_report` writes ``metrics.json``, ``report.md`` and the figures.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from ..learn.replay_env import ReplayEnvConfig, ReplaySim, runaway
from ..learn.residual import observation

__all__ = ["Metrics", "rollout", "metrics", "evaluate_split", "plot_fig3", "learning_curves", "plot_learning_curves",
           "write_report"]


@dataclass(frozen=True)
class Metrics:
    """Errors of simulated vs recorded joint states over all joints and samples of a set of trajectories."""

    mean_abs_dq: float
    """mean |q_sim − q_real| [rad]."""
    std_abs_dq: float
    """std of |q_sim − q_real| [rad]."""
    rmse_dq: float
    """root mean square of q_sim − q_real [rad]."""
    max_abs_dq: float
    """max |q_sim − q_real| [rad]."""
    per_joint_rmse: list[float]
    """RMSE per joint [rad], shape (n_dof,)."""
    mean_abs_dqd: float
    """mean |q̇_sim − q̇_real| [rad/s]."""
    rmse_dqd: float
    """root mean square of q̇_sim − q̇_real [rad/s]."""
    diverged: int
    """Trajectories whose replay diverged (left out of the numbers above)."""


def _policy_device(policy) -> torch.device | None:
    if isinstance(policy, torch.nn.Module):
        for t in list(policy.parameters()) + list(policy.buffers()):
            return t.device
    return None


def rollout(robot, trajectories, rate_hz: float, policy=None, kind: str = "torque", solver: str = "auto",
            substeps: int = 1, device: str | None = "cpu", with_baseline: bool = True) -> dict:
    """Replay every trajectory open-loop from its first recorded state, in parallel worlds.

    Args:
        robot: The robot.
        trajectories: Recorded trajectories (``q``, ``qd``, ``qdd``, ``q_cmd``; ``tau`` is never read).
        rate_hz: Sample rate of the recordings [Hz]; command k is held for one sample period.
        policy: Residual ``policy(obs) -> residual`` or ``None`` for PD only.
        kind: ``"torque"`` (residual [N*m] added to the PD torque) or ``"delta_action"`` ([rad] added to q_cmd).
        solver, substeps, device: Simulation settings (see :class:`~wresdyn.learn.replay_env.ReplayEnvConfig`).
        with_baseline: Also run PD-only in extra worlds of the same batch.

    Returns:
        ``{"residual": [(q, qd), ...], "pd": [(q, qd), ...]}``: simulated joint positions [rad] and velocities
        [rad/s] per trajectory, each (T_i, n_dof); a replay that diverged holds NaN from the divergence on.
        ``"residual"`` is absent without a policy, ``"pd"`` without the baseline.
    """
    dt = 1.0 / rate_hz
    w = len(trajectories)
    lengths = [len(t.q) for t in trajectories]
    t_max = max(lengths)

    def stack(name):  # pad shorter trajectories by holding their last sample
        return np.stack([np.concatenate([getattr(t, name), np.repeat(getattr(t, name)[-1:], t_max - len(t.q), 0)])
                         for t in trajectories])

    groups = (["pd"] if with_baseline or policy is None else []) + (["residual"] if policy is not None else [])
    n_worlds = w * len(groups)
    sim = ReplaySim(robot, n_worlds, dt, solver, substeps, device)
    dev = sim.device
    cmd = torch.as_tensor(np.tile(stack("q_cmd"), (len(groups), 1, 1)), dtype=torch.float32, device=dev)
    q0 = torch.as_tensor(np.tile(stack("q")[:, 0], (len(groups), 1)), dtype=torch.float32, device=dev)
    qd0 = torch.as_tensor(np.tile(stack("qd")[:, 0], (len(groups), 1)), dtype=torch.float32, device=dev)
    qdd = torch.as_tensor(np.tile(stack("qdd")[:, 0], (len(groups), 1)), dtype=torch.float32, device=dev)
    sim.set_state(torch.arange(n_worlds, device=dev), q0, qd0)
    lower = torch.as_tensor(robot.lower, dtype=torch.float32, device=dev)
    upper = torch.as_tensor(robot.upper, dtype=torch.float32, device=dev)
    no_error_limit = ReplayEnvConfig(max_error=float("inf"))
    res_ids = slice(groups.index("residual") * w, (groups.index("residual") + 1) * w) if policy is not None else None
    pdev = _policy_device(policy)
    if policy is not None and hasattr(policy, "reset"):
        policy.reset()
    out_q = torch.empty(n_worlds, t_max, robot.n_dof, device=dev)
    out_qd = torch.empty_like(out_q)
    q, qd = sim.q, sim.qd
    out_q[:, 0], out_qd[:, 0] = q, qd
    dead = torch.zeros(n_worlds, dtype=torch.bool, device=dev)
    for k in range(t_max - 1):
        target, tau = cmd[:, k].clone(), torch.zeros_like(q)
        if policy is not None:
            obs = observation(q[res_ids], qd[res_ids], qdd[res_ids], cmd[res_ids, k])
            with torch.no_grad():
                r = policy(obs if pdev is None else obs.to(pdev)).to(dev)
            if kind == "torque":
                tau[res_ids] = r
            else:
                target[res_ids] += r
        q_new, qd_new = sim.step(target, tau)
        qdd = (qd_new - qd) / dt
        bad = runaway(q_new, qd_new, q_new, lower, upper, no_error_limit) & ~dead
        if bad.any():  # keep NaN out of the policy and the solver; the world is reported as diverged
            dead |= bad
            ids = bad.nonzero().squeeze(-1)
            sim.set_state(ids, q0[ids], qd0[ids])
            q_new, qd_new = sim.q, sim.qd
            qdd[ids] = 0.0
        q, qd = q_new, qd_new
        out_q[:, k + 1] = torch.where(dead[:, None], torch.nan, q)
        out_qd[:, k + 1] = torch.where(dead[:, None], torch.nan, qd)
    out_q, out_qd = out_q.cpu().double().numpy(), out_qd.cpu().double().numpy()
    return {g: [(out_q[i * w + j, :lengths[j]], out_qd[i * w + j, :lengths[j]]) for j in range(w)]
            for i, g in enumerate(groups)}


def metrics(trajectories, sims) -> Metrics:
    """:class:`Metrics` of simulated ``sims`` [(q, qd), ...] against the recorded ``trajectories``."""
    ok = [(t, s) for t, s in zip(trajectories, sims) if np.isfinite(s[0]).all()]
    if not ok:
        nan = float("nan")
        return Metrics(nan, nan, nan, nan, [nan] * trajectories[0].q.shape[1], nan, nan, len(trajectories))
    dq = np.concatenate([s[0] - t.q for t, s in ok])
    dqd = np.concatenate([s[1] - t.qd for t, s in ok])
    return Metrics(
        mean_abs_dq=float(np.abs(dq).mean()),
        std_abs_dq=float(np.abs(dq).std()),
        rmse_dq=float(np.sqrt((dq**2).mean())),
        max_abs_dq=float(np.abs(dq).max()),
        per_joint_rmse=[float(x) for x in np.sqrt((dq**2).mean(0))],
        mean_abs_dqd=float(np.abs(dqd).mean()),
        rmse_dqd=float(np.sqrt((dqd**2).mean())),
        diverged=len(trajectories) - len(ok),
    )


def evaluate_split(robot, trajectories, rate_hz: float, policy=None, kind: str = "torque", solver: str = "auto",
                   substeps: int = 1, device: str | None = "cpu") -> tuple[dict, dict]:
    """PD-only and PD + residual metrics for one split.

    Returns:
        ``(summary, rollouts)``: summary ``{"pd_only": Metrics-dict, "pd_residual": Metrics-dict | None,
        "improvement": mean |Δq| PD-only / PD + residual, "n_trajectories", "seconds"}`` and the rollouts
        of :func:`rollout`.
    """
    from dataclasses import asdict

    runs = rollout(robot, trajectories, rate_hz, policy, kind, solver, substeps, device)
    pd = metrics(trajectories, runs["pd"])
    res = metrics(trajectories, runs["residual"]) if "residual" in runs else None
    summary = {
        "n_trajectories": len(trajectories),
        "seconds": float(sum(len(t.q) - 1 for t in trajectories) / rate_hz),
        "pd_only": asdict(pd),
        "pd_residual": asdict(res) if res else None,
        "improvement": (pd.mean_abs_dq / res.mean_abs_dq) if res and res.mean_abs_dq > 0 else None,
    }
    return summary, runs


def plot_fig3(robot, traj, runs: dict, path: str | Path, rate_hz: float, n_joints: int = 6, title: str = "") -> Path:
    """Fig. 3-style plot of one trajectory: real (red), PD only (green), PD + residual (blue), for the
    ``n_joints`` joints with the largest PD-only error."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    j_traj = 0
    q_pd = runs["pd"][j_traj][0]
    q_res = runs["residual"][j_traj][0] if "residual" in runs else None
    joints = np.argsort(-np.sqrt(np.nanmean((q_pd - traj.q) ** 2, axis=0)))[:n_joints]
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
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    curves: dict[str, dict[int, float]] = {}
    for f in sorted(Path(run_dir).glob("events.out.tfevents.*"), key=lambda p: p.stat().st_mtime):
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


def _fmt(m: dict | None) -> str:
    return "—" if not m else f"{m['mean_abs_dq']:.4f} ± {m['std_abs_dq']:.4f}"


def write_report(out_dir: str | Path, robot, results: dict, info: dict | None = None) -> Path:
    """Write ``metrics.json`` and ``report.md`` for ``results`` = {split: summary of :func:`evaluate_split`}."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = {"info": info or {}, "joint_names": list(robot.joint_names), "splits": results}
    (out / "metrics.json").write_text(json.dumps(doc, indent=2))
    lines = ["# Residual dynamics evaluation", ""]
    for k, v in (info or {}).items():
        lines.append(f"- {k}: `{v}`")
    lines += ["", "Open-loop replay from the first recorded state, whole trajectories. Mean |Δq| ± std over all "
              "joints and samples.", "",
              "| split | traj | PD only [rad] | PD + residual [rad] | improvement | vel. err PD / +res [rad/s] |",
              "|---|---|---|---|---|---|"]
    for split, s in results.items():
        pd, res = s["pd_only"], s["pd_residual"]
        imp = f"{s['improvement']:.1f}×" if s.get("improvement") else "—"
        vel = f"{pd['mean_abs_dqd']:.3f} / " + (f"{res['mean_abs_dqd']:.3f}" if res else "—")
        lines.append(f"| {split} | {s['n_trajectories']} | {_fmt(pd)} | {_fmt(res)} | {imp} | {vel} |")
    lines += ["", "Per-joint RMSE [rad] (PD only → PD + residual):", "",
              "| joint | " + " | ".join(results) + " |", "|---|" + "---|" * len(results)]
    for j, name in enumerate(robot.joint_names):
        cells = []
        for s in results.values():
            a = s["pd_only"]["per_joint_rmse"][j]
            b = s["pd_residual"]["per_joint_rmse"][j] if s["pd_residual"] else float("nan")
            cells.append(f"{a:.4f} → {b:.4f}")
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    figs = sorted(p.name for p in out.glob("*.png"))
    if figs:
        lines += [""] + [f"![{f}]({f})" for f in figs]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return out / "report.md"
