"""What the updates of an :class:`~wresdyn.adapt.adapter.Adapter` did, over time: the tracked parameters, a CSV and a
JSON of every update and a plot of the errors and the parameters' trajectories."""

from __future__ import annotations

import csv
import fnmatch
import json
from pathlib import Path

import numpy as np

from ..errors import WresdynError
from ..robot.physical import JOINT_FIELDS

__all__ = ["parameter_columns", "tracked_names", "write_updates", "plot_updates"]


def parameter_columns(params, fit) -> dict[str, float]:
    """Every adapted value of ``params`` (:class:`~wresdyn.robot.physical.PhysicalParams`) by column name:
    ``FIELD[joint]`` for the joint fields of ``fit``, ``body_mass[body]`` [kg] with ``"bodies"`` in ``fit``."""
    out = {}
    for f in JOINT_FIELDS:
        if f in fit:
            out.update({f"{f}[{j}]": float(v) for j, v in zip(params.joint_names, getattr(params, f))})
    if "bodies" in fit:
        out.update({f"body_mass[{b}]": float(v) for b, v in zip(params.body_names, params.body_mass)})
    return out


def tracked_names(start, fit, patterns=(), top: int = 3, latest=None) -> list[str]:
    """Columns of :func:`parameter_columns` to print: those matching ``patterns`` (``FIELD:NAME`` with an fnmatch
    pattern on the joint or body name, e.g. ``friction:*knee``), or without patterns the ``top`` that moved most,
    relative to the warm start ``start``, in ``latest`` (none yet: the first ``top``)."""
    cols = parameter_columns(start, fit)
    if patterns:
        names = []
        for p in patterns:
            field, _, name = p.partition(":")
            hits = [c for c in cols if c.startswith(field + "[") and fnmatch.fnmatchcase(c[len(field) + 1:-1],
                                                                                      name or "*")]
            if not hits:
                raise WresdynError(f"--track {p}: matches no adapted parameter (FIELD:NAME, FIELD one of "
                                   f"{sorted({c.split('[')[0] for c in cols})})")
            names += [h for h in hits if h not in names]
        return names
    if latest is None:
        return list(cols)[:top]
    now = parameter_columns(latest, fit)
    change = {c: abs(now[c] - v) / max(abs(v), 1e-9) for c, v in cols.items() if np.isfinite(v)}
    return sorted(change, key=change.get, reverse=True)[:top]


def write_updates(out: Path, updates, fit, summary: dict) -> tuple[Path, Path]:
    """``updates.csv`` (one row per update: the scalar fields of :class:`~wresdyn.adapt.adapter_update.Update` and every
    adapted parameter) and ``updates.json`` (``summary`` and the rows) in ``out``."""
    rows = [{**u.row(), **parameter_columns(u.physics, fit)} for u in updates]
    csv_path, json_path = out / "updates.csv", out / "updates.json"
    with open(csv_path, "w", newline="") as f:
        if rows:
            w = csv.DictWriter(f, fieldnames=list(rows[0]))
            w.writeheader()
            w.writerows(rows)
    json_path.write_text(json.dumps({**summary, "updates": rows}, indent=1))
    return csv_path, json_path


def plot_updates(path: Path, updates, start, names: list[str]) -> Path:
    """Two panels over robot time: the held-back open-loop error of the adapted model and of the warm start held
    fixed, and the one-step error; the parameters ``names`` relative to the warm start (where it is not 0)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.array([u.t for u in updates])
    fig, ax = plt.subplots(2, 1, figsize=(8, 6), sharex=True)
    ax[0].plot(t, [u.open_loop_start for u in updates], label="offline calibration, fixed")
    ax[0].plot(t, [u.open_loop for u in updates], label="adapted")
    ax[0].plot(t, [u.one_step for u in updates], ":", label="adapted, one step")
    acc = [u.t for u in updates if u.accepted]
    ax[0].plot(acc, [u.open_loop for u in updates if u.accepted], "|", color="k", label="accepted update")
    ax[0].set_ylabel("mean |q_sim - q| [rad]")
    ax[0].set_yscale("log")
    ax[0].legend(fontsize=8)
    ref = parameter_columns(start, {n.split("[")[0] for n in names} | {"bodies"})
    for n in names:
        vals = [parameter_columns(u.physics, {n.split("[")[0]} | {"bodies"})[n] for u in updates]
        if ref[n] != 0:
            ax[1].plot(t, np.array(vals) / ref[n], label=n)
        else:  # nothing to divide by (a friction the warm start does not have): the value itself
            ax[1].plot(t, vals, label=f"{n} (value, warm start 0)")
    ax[1].set_ylabel("value / warm start")
    ax[1].set_xlabel("robot time [s]")
    ax[1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
