"""What if the fitted zoo model had other drive parameters: the fit's residual replayed (as ``wresdyn eval``) on its
identified physics with some fields swapped, per split ratio PD only / model and per-trajectory mean |Δq|.

Variants (each a copy of ``fit/physics.json``):

* ``fitted``: as identified (the zoo's result);
* ``shared_ratio``: the effort limits of the joints that never saturate in training set to the saturating joints'
  median identified / file ratio times the file's, WITHOUT the lower bound of the largest demanded torque
  (:mod:`wresdyn.identify.unexcited_limits` keeps the bound): the candidate default;
* ``true_effort``: every effort limit the truth's (oracle);
* ``true_effort_kd_damping``: and kd, damping the truth's (oracle: the PD / viscous split that only shows while a
  drive saturates);
* ``true_drive``: kp, kd, damping, friction, effort the truth's (oracle).

    python benchmarks/fidelity/robot_zoo/what_if.py ROBOT_DIR [...] [--data-root DIR] [--fit-root DIR]

Writes ``what_if.json`` into each ROBOT_DIR.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from diagnose import load

SPLITS = ("validation", "heldout", "ood")


def variants(ds, robot, params, truth) -> dict:
    from wresdyn.identify.unexcited_limits import limit_unexcited_efforts

    _, found = limit_unexcited_efforts(params, robot.effort, ds.split("train"), 1.0 / ds.rate_hz,
                                       fitted=ds.fit_weights() > 0)
    shared = params.copy()
    if found.ratio is not None:
        unseen = found.saturated < 0.01
        shared.effort = np.where(unseen & np.isfinite(robot.effort), found.ratio * np.asarray(robot.effort),
                                 params.effort)
    out = {"fitted": params, "shared_ratio": shared}
    for name, fields in (("true_effort", ("effort",)), ("true_effort_kd_damping", ("effort", "kd", "damping")),
                         ("true_drive", ("effort", "kd", "damping", "friction", "kp"))):
        p = params.copy()
        for f in fields:
            setattr(p, f, np.array(getattr(truth, f), dtype=np.float64))
        out[name] = p
    return out


def what_if(robot_dir: Path, data_root=None, fit_root=None) -> dict:
    from wresdyn.evaluation.evaluate_run import load_run_model, run_friction_kappa
    from wresdyn.evaluation.open_loop import evaluate_splits

    ds, robot, params, real, fit = load(robot_dir, data_root, fit_root)
    policy, meta, _, solver, substeps = load_run_model(fit, robot, ds.rate_hz)
    splits = {s: ds.split(s) for s in SPLITS}
    result = {}
    for name, p in variants(ds, robot, params, real.physics()).items():
        done = evaluate_splits(robot, splits, ds.rate_hz, policy, meta["kind"], solver, substeps, "cpu", physics=p,
                               weights=ds.fit_weights(), friction_kappa=run_friction_kappa(fit))
        row = {"effort": np.asarray(p.effort).tolist()}
        for s, (summary, runs) in done.items():
            per = {t.name: float(np.abs(q - t.q).mean()) for t, q in zip(splits[s], runs["residual"].q)}
            row[s] = {"ratio": summary["improvement"], "mean_abs_dq": summary["pd_residual"]["mean_abs_dq"],
                      "per_trajectory": per}
        result[name] = row
        print(robot_dir.name, name, "  ".join(f"{s} {row[s]['ratio']:.1f}x" for s in SPLITS), flush=True)
    (robot_dir / "what_if.json").write_text(json.dumps(result, indent=1) + "\n")
    return result


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("robot_dirs", nargs="+", type=Path)
    p.add_argument("--data-root", type=Path, default=None)
    p.add_argument("--fit-root", type=Path, default=None)
    args = p.parse_args(argv)
    import torch

    torch.set_num_threads(1)
    for d in args.robot_dirs:
        what_if(d.resolve(), args.data_root, args.fit_root)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
