"""Identification report: identified physical parameters against the truth, and what the excitation can identify.

For a dataset recorded on the simulated real robot the truth is known: :meth:`wresdyn.data.real_robot.RealRobot.physics`
reads it back from the perturbed MuJoCo model. Per joint the report shows each identified field, the true value
and their ratio, and two properties of the training recordings that decide what the data can tell:

- **moving**: fraction of samples with |q̇| above :data:`MOVING_SPEED`; a joint that rarely leaves its dry-friction
  dead band shows its friction only as a threshold, and its inertia, damping and gains hardly at all;
- **saturated**: fraction of samples where the true drive torque |kp·(q_cmd − q) − kd·q̇| exceeds the true effort
  limit (computed with the truth, never available to the learner); a limit the excitation never reaches cannot
  be identified, only bounded from below.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..data.dataset import MOVING_SPEED

__all__ = ["excitation_coverage", "identification_table", "write_identification_report", "MOVING_SPEED"]

FIELDS = ("kp", "kd", "armature", "damping", "friction", "effort", "delay")
UNITS = {"kp": "N·m/rad", "kd": "N·m·s/rad", "armature": "kg·m²", "damping": "N·m·s/rad", "friction": "N·m",
         "effort": "N·m", "delay": "ms"}


def excitation_coverage(trajectories, truth) -> dict[str, np.ndarray]:
    """Per joint, over the recordings: fraction moving and fraction with the true drive saturated, (n,) each."""
    q = np.concatenate([t.q for t in trajectories])
    qd = np.concatenate([t.qd for t in trajectories])
    cmd = np.concatenate([t.q_cmd for t in trajectories])
    moving = (np.abs(qd) > MOVING_SPEED).mean(0)
    if truth is None:
        return {"moving": moving}
    tau = truth.kp * (cmd - q) - truth.kd * qd
    return {"moving": moving, "saturated": (np.abs(tau) > truth.effort).mean(0)}


def identification_table(identified, truth, coverage: dict) -> list[dict]:
    """One row per joint and field: identified, true, ratio, and whether the field counts as identifiable here."""
    rows = []
    for j, name in enumerate(identified.joint_names):
        for f in FIELDS:
            a = float(getattr(identified, f)[j])
            b = float(getattr(truth, f)[j]) if truth is not None else float("nan")
            ident = coverage["moving"][j] >= 0.05
            if f == "effort" and "saturated" in coverage:
                ident = ident and coverage["saturated"][j] >= 0.01
            rows.append({"joint": name, "field": f, "identified": a, "true": b,
                         "ratio": a / b if truth is not None and b != 0 and np.isfinite(b) else float("nan"),
                         "identifiable": bool(ident)})
    return rows


def write_identification_report(out_dir, identified, truth, trajectories, extra: str = "") -> Path:
    """Write ``identification.md``, ``identification.json`` and ``identification.png`` to ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    cov = excitation_coverage(trajectories, truth)
    rows = identification_table(identified, truth, cov)
    (out_dir / "identification.json").write_text(json.dumps({"rows": rows, **{k: v.tolist() for k, v in cov.items()}},
                                                            indent=1))
    scale = {f: (1e3 if f == "delay" else 1.0) for f in FIELDS}
    lines = ["# Identified physical parameters", ""]
    if extra:
        lines += [extra, ""]
    if truth is None:
        lines += ["No ground truth (recorded on hardware): identified values only.", ""]
    lines += ["Per joint: identified / true (ratio). `moving`: fraction of training samples with |q̇| > "
              f"{MOVING_SPEED} rad/s; `sat.`: fraction where the true drive saturates. Ratios in **bold** are off by "
              "more than 10 % on a joint the excitation moves (≥ 5 % of samples; for the effort limit also "
              "saturated ≥ 1 %).", ""]
    head = "| joint | moving | sat. | " + " | ".join(f"{f} [{UNITS[f]}]" for f in FIELDS) + " |"
    lines += [head, "|" + "---|" * (3 + len(FIELDS))]
    by = {(r["joint"], r["field"]): r for r in rows}
    within, counted = 0, 0
    for j, name in enumerate(identified.joint_names):
        cells = []
        for f in FIELDS:
            r = by[(name, f)]
            a = r["identified"] * scale[f]
            if truth is None:
                cells.append(f"{a:.4g}")
                continue
            b = r["true"] * scale[f]
            ratio = r["ratio"]
            off = np.isfinite(ratio) and abs(ratio - 1) > 0.1
            if r["identifiable"] and np.isfinite(ratio):
                counted += 1
                within += not off
            txt = f"{ratio:.2f}" if np.isfinite(ratio) else "–"
            cells.append(f"{a:.3g} / {b:.3g} ({'**' + txt + '**' if off and r['identifiable'] else txt})")
        sat = f"{cov['saturated'][j]:.2f}" if "saturated" in cov else "–"
        lines.append(f"| {name} | {cov['moving'][j]:.2f} | {sat} | " + " | ".join(cells) + " |")
    if truth is not None:
        lines += ["", f"Within 10 % of the truth: {within} of {counted} identifiable (joint, field) pairs."]
        lines += ["", "Links (mass identified / true): " + ", ".join(
            f"{n} {a:.2f}/{b:.2f}" for n, a, b in zip(identified.body_names, identified.body_mass, truth.body_mass)
            if b > 0)]
    (out_dir / "identification.md").write_text("\n".join(lines) + "\n")
    if truth is not None:
        _plot(out_dir / "identification.png", rows, identified.joint_names)
    return out_dir / "identification.md"


def _plot(path: Path, rows, joint_names) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(FIELDS), 1, figsize=(12, 1.6 * len(FIELDS)), sharex=True)
    x = np.arange(len(joint_names))
    for ax, f in zip(axes, FIELDS):
        r = [row for row in rows if row["field"] == f]
        ratio = np.array([row["ratio"] for row in r])
        ok = np.array([row["identifiable"] for row in r])
        ax.bar(x[ok], ratio[ok], color="tab:blue")
        ax.bar(x[~ok], ratio[~ok], color="lightgray")
        ax.axhspan(0.9, 1.1, color="tab:green", alpha=0.15)
        ax.axhline(1.0, color="k", lw=0.8)
        ax.set_ylabel(f, rotation=0, ha="right")
        ax.set_ylim(0, 2.5)
    axes[-1].set_xticks(x, joint_names, rotation=60, ha="right", fontsize=7)
    axes[0].set_title("identified / true (grey: the excitation does not identify it; green band: ±10 %)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
