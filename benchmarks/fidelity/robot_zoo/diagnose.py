"""Why a zoo robot falls short: where its error sits and whether the real robot's drives saturate where training
never showed it.

For each finished robot folder (``OUT/<robot>/`` of ``run.py``: ``data/dataset.npz`` and the fit's run folder
``fit/``) it writes into that folder:

* ``identifiability.json`` / ``.md``: the identifiability report of the fit's identified physics
  (:func:`wresdyn.identify.identifiability.identifiability`, under the fit's stage-1 settings);
* ``diagnosis.json`` / ``.md``:

  - per split, trajectory and joint, the open-loop RMSE of PD only and of the fitted model (identified physics +
    residual), replayed as ``wresdyn eval`` does (``metrics.json`` has per-joint errors per split only);
  - per split and joint, the fraction of samples on which the REAL robot's drive saturates: the recorded
    (applied) torque |τ| at the true derated limit (within :data:`AT_LIMIT`), and the demanded PD torque of the
    true gains and delay above it (:func:`wresdyn.identify.unexcited_limits.demanded_torque`); beside it the same
    fraction for the identified model (its demanded torque over its identified limit);
  - per joint, the effort limit of the file, the truth (the mismatch applied by ``collect``,
    :meth:`wresdyn.data.real_robot.RealRobot.physics`) and the identified one;
  - per split and joint, the largest static gravity torque on the recorded poses (the real robot's MuJoCo model,
    q̇ = 0) against the true limit: a joint whose drive cannot hold the arm saturates whatever the command.

    python benchmarks/fidelity/robot_zoo/diagnose.py benchmarks/results/robot_zoo/ur5 [ROBOT_DIR ...] [--out-root DIR]

``--data-root`` / ``--fit-root``: read ``data/`` and ``fit/`` from another checkout's robot folder of the same
name (the datasets stay out of git); outputs always go to ROBOT_DIR.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

SPLITS = ("train", "validation", "heldout", "ood")
AT_LIMIT = 0.99
"""|τ| ≥ this × the true limit counts as saturated: the recorded torque is a substep average, quantised to 2^-8
N·m, so a drive held at its limit reads a hair below it."""
GRAVITY_STRIDE = 10
"""Every this many samples enter the static gravity torque (50 Hz at 500 Hz: poses change slowly)."""


def load(robot_dir: Path, data_root: Path | None, fit_root: Path | None):
    """``(dataset, robot, identified params, truth, fit folder)`` of a zoo robot folder."""
    from wresdyn.data.loading import load_data
    from wresdyn.data.mismatch import Mismatch
    from wresdyn.data.real_robot import RealRobot
    from wresdyn.learn.runs import run_physics

    name = robot_dir.name
    data = (data_root / name if data_root else robot_dir) / "data" / "dataset.npz"
    fit = (fit_root / name if fit_root else robot_dir) / "fit"
    ds, robot = load_data(str(data))
    params = run_physics(fit, robot)
    real = RealRobot(robot, Mismatch.from_dict(ds.mismatch), ds.rate_hz)
    return ds, robot, params, real, fit


def sysid_config(fit: Path):
    """The fit's stage-1 settings (``fit/identify/config.json``) as a :class:`SysIdConfig`, on the CPU."""
    from wresdyn.identify.sysid_config import SysIdConfig

    saved = json.loads((fit / "identify" / "config.json").read_text())["sysid"]
    known = {f.name: f for f in dataclasses.fields(SysIdConfig)}
    values = {k: tuple(v) if isinstance(v, list) else v for k, v in saved.items() if k in known}
    return dataclasses.replace(SysIdConfig(), **{**values, "device": "cpu"})


def replay_errors(ds, robot, fit: Path) -> dict:
    """Per split: ``{"trajectories": [{name, pd_rmse (n,), fit_rmse (n,), fit_mean_abs}], "improvement"}``."""
    from wresdyn.evaluation.evaluate_run import load_run_model, run_friction_kappa
    from wresdyn.evaluation.open_loop import evaluate_splits

    policy, meta, physics, solver, substeps = load_run_model(fit, robot, ds.rate_hz)
    splits = {s: ds.split(s) for s in SPLITS[1:] if ds.split(s)}
    done = evaluate_splits(robot, splits, ds.rate_hz, policy, meta["kind"], solver, substeps, "cpu", physics=physics,
                           weights=ds.fit_weights(), friction_kappa=run_friction_kappa(fit))
    out = {}
    for split, (summary, runs) in done.items():
        rows = []
        for k, t in enumerate(splits[split]):
            pd, res = runs["pd"].q[k] - t.q, runs["residual"].q[k] - t.q
            rows.append({"name": t.name, "pd_rmse": np.sqrt((pd ** 2).mean(0)).tolist(),
                         "fit_rmse": np.sqrt((res ** 2).mean(0)).tolist(),
                         "pd_mean_abs": float(np.abs(pd).mean()), "fit_mean_abs": float(np.abs(res).mean()),
                         "fit_max_abs": np.abs(res).max(0).tolist()})
        out[split] = {"improvement": summary["improvement"], "trajectories": rows}
    return out


def saturation(ds, robot, params, real) -> dict:
    """Per split: fractions of samples saturated per joint (recorded |τ|, true demand, identified demand) and the
    static gravity torque's maximum; per trajectory the recorded fraction."""
    import mujoco

    from wresdyn.identify.unexcited_limits import demanded_torque

    truth, dt = real.physics(), 1.0 / ds.rate_hz
    m, d = real.model, mujoco.MjData(real.model)
    n = robot.n_dof
    out = {}
    for split in SPLITS:
        trajs = ds.split(split)
        if not trajs:
            continue
        row = {"demand_true": (demanded_torque(truth, trajs, dt) > truth.effort).mean(0).tolist(),
               "demand_identified": (demanded_torque(params, trajs, dt) > params.effort).mean(0).tolist()}
        if all(t.tau is not None for t in trajs):
            at = [np.abs(t.tau) >= AT_LIMIT * truth.effort for t in trajs]
            row["recorded"] = np.concatenate(at).mean(0).tolist()
            row["per_trajectory"] = {t.name: a.mean(0).tolist() for t, a in zip(trajs, at)}
            row["tau_max"] = np.max([np.abs(t.tau).max(0) for t in trajs], axis=0).tolist()
        grav = []
        for t in trajs:
            for q in t.q[::GRAVITY_STRIDE]:
                d.qpos[:n], d.qvel[:] = q, 0.0
                mujoco.mj_forward(m, d)
                grav.append(d.qfrc_bias[:n].copy())
        g = np.abs(np.array(grav))
        row["gravity_max"] = g.max(0).tolist()
        row["gravity_over_limit"] = (g > truth.effort).mean(0).tolist()
        row["q_range"] = [np.min([t.q.min(0) for t in trajs], 0).tolist(),
                          np.max([t.q.max(0) for t in trajs], 0).tolist()]
        out[split] = row
    return out


def _f(x, p=3):
    return f"{x:.{p}g}"


def markdown(name, joints, errors, sat, limits, found) -> str:
    lines = [f"# {name}: diagnosis", "",
             f"Written by `benchmarks/fidelity/robot_zoo/diagnose.py`. Limits [N·m]: file / true (mismatch) / identified "
             "(`fit/physics.json`).", "",
             "| joint | file | true | identified | identified / true |", "|---|---|---|---|---|"]
    for j, jn in enumerate(joints):
        f_, t_, i_ = limits["file"][j], limits["true"][j], limits["identified"][j]
        lines.append(f"| {jn} | {_f(f_)} | {_f(t_)} | {_f(i_)} | {i_ / t_:.2f} |")
    lines += ["", "## Saturation of the real robot, per split and joint", "",
              f"Fraction of samples: `rec` recorded |τ| ≥ {AT_LIMIT} × true limit; `dem` true PD demand above the "
              "true "
              "limit; `id` the identified model's demand above its identified limit. `g/lim`: largest static gravity "
              "torque on the split's poses over the true limit.", "",
              "| split | " + " | ".join(joints) + " |", "|---|" + "---|" * len(joints)]
    for split, r in sat.items():
        cells = []
        for j in range(len(joints)):
            rec = f"{r['recorded'][j]:.3f}" if "recorded" in r else "–"
            cells.append(f"rec {rec} / dem {r['demand_true'][j]:.3f} / id {r['demand_identified'][j]:.3f} / g/lim "
                         f"{r['gravity_max'][j] / limits['true'][j]:.2f}")
        lines.append(f"| {split} | " + " | ".join(cells) + " |")
    lines += ["", "## Open-loop error per trajectory (RMSE per joint [rad], fitted model; PD only in brackets)", ""]
    for split, e in errors.items():
        lines += [f"### {split} (ratio {e['improvement']:.1f}×)", "",
                  "| trajectory | mean abs PD / fit | " + " | ".join(joints)
                  + " | recorded saturation (joints > 1 %) |",
                  "|---|---|" + "---|" * len(joints) + "---|"]
        per = sat.get(split, {}).get("per_trajectory", {})
        for t in e["trajectories"]:
            s = per.get(t["name"])
            sats = ", ".join(f"{joints[j]} {s[j]:.2f}" for j in range(len(joints)) if s and s[j] > 0.01) or "–"
            lines.append(f"| {t['name']} | {t['pd_mean_abs']:.4f} / {t['fit_mean_abs']:.4f} | " + " | ".join(
                f"{a:.4f} ({b:.3f})" for a, b in zip(t["fit_rmse"], t["pd_rmse"])) + f" | {sats} |")
        lines.append("")
    if found is not None:
        lines += [found.markdown()]
    return "\n".join(lines) + "\n"


def diagnose(robot_dir: Path, data_root: Path | None = None, fit_root: Path | None = None) -> dict:
    from wresdyn.identify.identifiability import identifiability, write_identifiability

    ds, robot, params, real, fit = load(robot_dir, data_root, fit_root)
    truth = real.physics()
    found = identifiability(robot, ds, params, sysid_config(fit))
    if found is not None:
        write_identifiability(robot_dir, found)
    errors = replay_errors(ds, robot, fit)
    sat = saturation(ds, robot, params, real)
    limits = {"file": np.asarray(robot.effort, float).tolist(), "true": np.asarray(truth.effort, float).tolist(),
              "identified": np.asarray(params.effort, float).tolist()}
    out = {"robot": robot_dir.name, "joints": list(robot.joint_names), "effort": limits, "saturation": sat,
           "errors": errors, "identifiability_flags": found.flags if found is not None else None}
    (robot_dir / "diagnosis.json").write_text(json.dumps(out, indent=1) + "\n")
    (robot_dir / "diagnosis.md").write_text(markdown(robot_dir.name, list(robot.joint_names), errors, sat, limits,
                                                     found))
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("robot_dirs", nargs="+", type=Path, help="zoo robot folders (OUT/<robot>/)")
    p.add_argument("--data-root", type=Path, default=None, help="read <root>/<robot>/data/ instead of ROBOT_DIR's")
    p.add_argument("--fit-root", type=Path, default=None, help="read <root>/<robot>/fit/ instead of ROBOT_DIR's")
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    for d in args.robot_dirs:
        diagnose(d.resolve(), args.data_root, args.fit_root)
        print(f"wrote {d / 'diagnosis.md'}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
