"""Open-loop evaluation of a residual: PD-only vs PD + residual vs the recording (paper Sec. III-A, Fig. 3).

Each trajectory of a split is replayed from its first recorded state for its whole length, driven only by
the recorded commands, once with PD alone and once with the residual in the loop (deterministic), in one batch
of worlds through the simulation layer's rollout (:func:`wresdyn.sim.rollout`). The headline number is the
mean |Δq| = |q_sim − q_real| over all joints and samples [rad], ± its std.

Joints a dataset excludes from fitting (its mapping file's ``[exclude]``, e.g. a gripper:
:attr:`~wresdyn.data.dataset.Dataset.excluded_joints`) are replayed like the others but left out of every
average: pass ``weights=dataset.fit_weights()`` (1 fitted, 0 excluded) and the summary and report name them.

Diverged replays are never dropped: a world that diverges holds its last sane state to the end of the
trajectory (the robot "stops"), so its growing error to the recording counts against the model, and the
number of diverged trajectories is reported next to every figure. PD-only and PD + residual are averaged over
the same trajectories.

:func:`evaluate_split` (:func:`evaluate_splits`: several splits in one batch) takes any residual
``policy(obs) -> residual`` (a torch module mapping raw [q, q̇, q̈, q_cmd] (N, 4n) to N*m or rad, (N, n), with an
optional ``reset()``); :func:`write_report` writes ``metrics.json`` and ``report.md``; :func:`pd_gap` is the PD-only
gap of a set of recordings.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..data.dataset import fitted_mask
from ..sim.rollout import Replays, replay_trajectories

__all__ = ["Metrics", "fitted_mask", "excluded_names", "metrics", "evaluate_split", "evaluate_splits", "pd_gap",
           "summary_line", "write_report"]


@dataclass(frozen=True)
class Metrics:
    """Errors of simulated vs recorded joint states over the fitted joints (all joints unless some are excluded)
    and all samples of a set of trajectories."""

    mean_abs_dq: float
    """mean |q_sim − q_real| [rad]."""
    std_abs_dq: float
    """std of |q_sim − q_real| [rad]."""
    rmse_dq: float
    """root mean square of q_sim − q_real [rad]."""
    max_abs_dq: float
    """max |q_sim − q_real| [rad]."""
    per_joint_rmse: list[float]
    """RMSE per joint [rad], shape (n_dof,): every joint, excluded ones too (for the report)."""
    mean_abs_dqd: float
    """mean |q̇_sim − q̇_real| [rad/s]."""
    rmse_dqd: float
    """root mean square of q̇_sim − q̇_real [rad/s]."""
    n_trajectories: int
    """Trajectories evaluated (all of them count in the numbers above)."""
    diverged: int
    """Trajectories whose replay diverged; from the divergence on they hold their last sane state."""
    diverged_names: list[str]
    """Names of the diverged trajectories."""
    n_joints: int = 0
    """Joints the averages above run over (the fitted ones)."""


def excluded_names(joint_names, weights) -> list[str]:
    """Names of the joints ``weights`` excludes (weight 0), in order; ``[]`` for ``None``."""
    return [j for j, m in zip(joint_names, fitted_mask(weights, len(joint_names))) if not m]


def metrics(trajectories, replays, weights=None) -> Metrics:
    """:class:`Metrics` of ``replays`` against the recorded ``trajectories`` (every trajectory counts), averaged
    over the joints with ``weights > 0`` (per-joint weights (n_dof,), :func:`fitted_mask`; ``None``: all)."""
    dq_all = np.concatenate([q - t.q for t, q in zip(trajectories, replays.q)])
    mask = fitted_mask(weights, dq_all.shape[1])
    dq = dq_all[:, mask]
    dqd = np.concatenate([qd - t.qd for t, qd in zip(trajectories, replays.qd)])[:, mask]
    names = [getattr(t, "name", str(i)) for i, (t, a) in enumerate(zip(trajectories, replays.diverged_at)) if a >= 0]
    return Metrics(
        mean_abs_dq=float(np.abs(dq).mean()),
        std_abs_dq=float(np.abs(dq).std()),
        rmse_dq=float(np.sqrt((dq**2).mean())),
        max_abs_dq=float(np.abs(dq).max()),
        per_joint_rmse=[float(x) for x in np.sqrt((dq_all**2).mean(0))],
        mean_abs_dqd=float(np.abs(dqd).mean()),
        rmse_dqd=float(np.sqrt((dqd**2).mean())),
        n_trajectories=len(trajectories),
        diverged=len(names),
        diverged_names=names,
        n_joints=int(mask.sum()),
    )


def evaluate_split(robot, trajectories, rate_hz: float, policy=None, kind: str | None = None, solver: str = "auto",
                   substeps: int = 1, device: str | None = "cpu", delay: float = 0.0, physics=None, weights=None,
                   friction_kappa: float | None = None) -> tuple[dict, dict]:
    """PD-only and PD + residual metrics for one split (``physics``: the model's physical parameters, see
    :func:`~wresdyn.sim.rollout.replay_trajectories`; "PD + residual" is then the calibrated model with its
    residual, or alone without a policy). ``weights`` (n_dof,): per-joint weights, joints with 0 are left out of
    the metrics (pass :meth:`~wresdyn.data.dataset.Dataset.fit_weights`); ``None``: every joint counts.
    ``friction_kappa``: the replay solver's dry-friction law (:class:`~wresdyn.sim.Simulator`), of both replays.

    Returns:
        ``(summary, replays)``: summary ``{"pd_only": Metrics-dict, "pd_residual": Metrics-dict | None,
        "improvement": mean |Δq| PD-only / PD + residual, "n_trajectories", "seconds", "excluded_joints": names
        left out of the metrics}`` and the replays of :func:`wresdyn.sim.rollout.replay_trajectories`.
    """
    return evaluate_splits(robot, {"split": trajectories}, rate_hz, policy, kind, solver, substeps, device, delay,
                           physics, weights, friction_kappa)["split"]


def evaluate_splits(robot, splits: dict, rate_hz: float, policy=None, kind: str | None = None, solver: str = "auto",
                    substeps: int = 1, device: str | None = "cpu", delay: float = 0.0, physics=None, weights=None,
                    friction_kappa: float | None = None) -> dict[str, tuple[dict, dict]]:
    """:func:`evaluate_split` for each split of ``splits`` (name -> trajectories), all replayed in one batch (on a GPU
    one step launch serves every split); returns name -> ``(summary, replays)``."""
    splits = {k: list(v) for k, v in splits.items()}
    if not all(splits.values()):
        raise ValueError("no trajectories to evaluate")
    excluded = excluded_names(robot.joint_names, weights)  # checks the weights before the replay
    every = [t for trajs in splits.values() for t in trajs]
    runs = replay_trajectories(robot, every, rate_hz, policy, kind=kind, solver=solver, substeps=substeps,
                               device=device, with_baseline=True, delay=delay, physics=physics,
                               friction_kappa=friction_kappa)
    out, first = {}, 0
    for name, trajectories in splits.items():
        part = slice(first, first + len(trajectories))
        first = part.stop
        own = {g: Replays(r.q[part], r.qd[part], r.diverged_at[part]) for g, r in runs.items()}
        pd = metrics(trajectories, own["pd"], weights)
        res = metrics(trajectories, own["residual"], weights) if "residual" in own else None
        out[name] = ({
            "n_trajectories": len(trajectories),
            "excluded_joints": excluded,
            "seconds": float(sum(len(t.q) - 1 for t in trajectories) / rate_hz),
            "pd_only": asdict(pd),
            "pd_residual": asdict(res) if res else None,
            "improvement": (pd.mean_abs_dq / res.mean_abs_dq) if res and res.mean_abs_dq > 0 else None,
        }, own)
    return out


def pd_gap(robot, trajectories, rate_hz: float, solver: str = "auto", device: str | None = "cpu",
           weights=None) -> dict:
    """The sim-to-real gap to close: PD-only Newton replay of each trajectory (nominal robot, open loop from the
    first recorded state, whole trajectory) against the recording. ``weights`` (n_dof,) as in
    :func:`evaluate_split`: joints with weight 0 are left out of ``mean``, ``std`` and ``per_trajectory``.

    Returns:
        ``{"mean": mean |Δq| [rad], "std": its std over all samples and fitted joints [rad], "per_trajectory":
        {name: mean |Δq|}, "per_joint": {joint: mean |Δq|} (every joint), "excluded_joints": [names],
        "n_trajectories": int, "diverged": int}``.
    """
    trajectories = list(trajectories)
    if not trajectories:
        return {}
    mask = fitted_mask(weights, robot.n_dof)
    runs = replay_trajectories(robot, trajectories, rate_hz, solver=solver, device=device)["pd"]
    errs = [np.abs(q - t.q) for t, q in zip(trajectories, runs.q)]
    e = np.concatenate(errs)
    return {"mean": float(e[:, mask].mean()), "std": float(e[:, mask].std()),
            "per_trajectory": {t.name: float(x[:, mask].mean()) for t, x in zip(trajectories, errs)},
            "per_joint": dict(zip(robot.joint_names, e.mean(axis=0).tolist())),
            "excluded_joints": excluded_names(robot.joint_names, weights),
            "n_trajectories": len(trajectories), "diverged": sum(a >= 0 for a in runs.diverged_at)}


def summary_line(split: str, s: dict) -> str:
    """One line per split for the terminal: PD only, PD + residual, the ratio, and what diverged."""
    pd, res = s["pd_only"], s["pd_residual"]
    line = f"{split:10s} {s['n_trajectories']} traj  mean |dq| PD only {pd['mean_abs_dq']:.4f} ± {pd['std_abs_dq']:.4f} rad"
    if res is not None:
        line += (f"  PD + residual {res['mean_abs_dq']:.4f} ± {res['std_abs_dq']:.4f} rad ({s['improvement']:.2f}x)"
                 f"  vel {pd['mean_abs_dqd']:.3f} -> {res['mean_abs_dqd']:.3f} rad/s")
        if res["diverged"] == res["n_trajectories"]:
            line += f"  ALL {res['diverged']} residual replays diverged (errors held from the divergence)"
        elif res["diverged"]:
            line += f"  {res['diverged']} residual replay(s) diverged: {', '.join(res['diverged_names'])}"
    if pd["diverged"]:
        line += f"  {pd['diverged']} PD-only replay(s) diverged"
    if s.get("excluded_joints"):
        line += f"  (over {pd['n_joints']} fitted joints; excluded: {', '.join(s['excluded_joints'])})"
    return line


def _fmt(m: dict | None) -> str:
    return "—" if not m else f"{m['mean_abs_dq']:.4f} ± {m['std_abs_dq']:.4f}"


def write_report(out_dir: str | Path, robot, results: dict, info: dict | None = None, figures=()) -> Path:
    """Write ``metrics.json`` and ``report.md`` for ``results`` = {split: summary of :func:`evaluate_split`}; the
    report shows the folder's figures and ``figures`` (names of those still being drawn)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    excluded = sorted({j for s in results.values() for j in s.get("excluded_joints", [])},
                      key=list(robot.joint_names).index)
    doc = {"info": info or {}, "joint_names": list(robot.joint_names), "excluded_joints": excluded,
           "splits": results}
    (out / "metrics.json").write_text(json.dumps(doc, indent=2))
    lines = ["# Residual dynamics evaluation", ""]
    for k, v in (info or {}).items():
        lines.append(f"- {k}: `{v}`")
    over = (f"the {len(robot.joint_names) - len(excluded)} fitted joints (excluded from fitting and from these "
            f"figures: {', '.join(excluded)})") if excluded else "all joints"
    lines += ["", f"Open-loop replay from the first recorded state, whole trajectories. Mean |Δq| ± std over {over} "
              "and samples of every trajectory; a replay that diverged holds its last sane state from there "
              "on and counts with that error.", "",
              "| split | traj | PD only [rad] | PD + residual [rad] | improvement | diverged PD / +res | "
              "vel. err PD / +res [rad/s] |",
              "|---|---|---|---|---|---|---|"]
    for split, s in results.items():
        pd, res = s["pd_only"], s["pd_residual"]
        imp = f"{s['improvement']:.1f}×" if s.get("improvement") else "—"
        div = f"{pd['diverged']} / " + (str(res["diverged"]) if res else "—")
        vel = f"{pd['mean_abs_dqd']:.3f} / " + (f"{res['mean_abs_dqd']:.3f}" if res else "—")
        lines.append(f"| {split} | {s['n_trajectories']} | {_fmt(pd)} | {_fmt(res)} | {imp} | {div} | {vel} |")
    diverged = [(split, s["pd_residual"]["diverged_names"]) for split, s in results.items()
                if s["pd_residual"] and s["pd_residual"]["diverged"]]
    for split, names in diverged:
        lines.append(f"\nDiverged with the residual ({split}): {', '.join(names)}.")
    lines += ["", "Per-joint RMSE [rad] (PD only → PD + residual):", "",
              "| joint | " + " | ".join(results) + " |", "|---|" + "---|" * len(results)]
    for j, name in enumerate(robot.joint_names):
        cells = []
        for s in results.values():
            a = s["pd_only"]["per_joint_rmse"][j]
            b = s["pd_residual"]["per_joint_rmse"][j] if s["pd_residual"] else float("nan")
            cells.append(f"{a:.4f} → {b:.4f}")
        lines.append(f"| {name}{' (excluded)' if name in excluded else ''} | " + " | ".join(cells) + " |")
    # a hidden one is a figure another process is still writing under a temporary name (wresdyn.cli.fit_tail)
    figs = sorted({p.name for p in out.glob("*.png") if not p.name.startswith(".")} | set(figures))
    if figs:
        lines += [""] + [f"![{f}]({f})" for f in figs]
    (out / "report.md").write_text("\n".join(lines) + "\n")
    return out / "report.md"
