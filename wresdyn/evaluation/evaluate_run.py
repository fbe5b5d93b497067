"""Evaluate a run folder (PPO or gradient fit) and write its report: what ``wresdyn eval RUN`` does."""

from __future__ import annotations

from ..learn.run_residual import load_policy
from ..learn.runs import RunError, run_physics
from ..ppo.ppo_config import config_from_dict
from ..sim.warmup import compile_kernels
from .open_loop import evaluate_splits, summary_line, write_report
from .plots import plot_fig3, plot_learning_curves

__all__ = ["evaluate_run", "load_run_model", "run_friction_kappa"]


def evaluate_run(run: str, ds, robot, splits=("validation", "heldout", "ood"), out: str | None = None, solver: str | None = None,
                 device: str = "cpu", joints: int = 6, compare=(), data_label: str = "", mark=None) -> dict:
    """Evaluate the exported residual of ``run`` on ``splits`` of ``ds`` and write the report; returns the
    per-split summaries. A run with ``physics.json`` (``wresdyn identify``, or a residual fitted on top of
    identified physics) replays its model with those parameters; a run with no residual evaluates the
    calibrated model under PD alone. Every replay runs under the run's own dry-friction law
    (:func:`run_friction_kappa`). ``mark``: called with a short note as each part ends (the model loaded, the splits
    replayed), for a clocked log; ``None``: nothing."""
    import json
    from pathlib import Path

    import torch

    torch.set_num_threads(1)
    run_dir = Path(run)
    policy, meta, physics, solver, substeps = load_run_model(run_dir, robot, ds.rate_hz, solver)
    kappa = run_friction_kappa(run_dir)
    out_dir = Path(out) if out else run_dir / "eval"

    compile_kernels(robot, ds.rate_hz, ("forward",), solver=solver, device=device)
    mark = mark or (lambda _: None)
    mark("evaluation: the model loaded")
    weights = ds.fit_weights()  # joints the dataset excludes from fitting count in no metric
    if ds.excluded_joints:
        print(f"excluded from fitting and from the metrics: {', '.join(ds.excluded_joints)}", flush=True)
    results = {}
    todo = {}
    for split in splits:
        trajs = ds.split(split)
        if trajs:
            todo[split] = trajs
        else:
            print(f"{split}: no trajectories, skipped")
    done = evaluate_splits(robot, todo, ds.rate_hz, policy, meta["kind"], solver, substeps, device, physics=physics,
                           weights=weights, friction_kappa=kappa) if todo else {}
    mark("evaluation: the splits replayed")
    for split, (summary, runs) in done.items():
        trajs = todo[split]
        results[split] = summary
        plot_fig3(robot, trajs[0], runs, out_dir / f"fig3_{split}.png", ds.rate_hz, joints,
                  title=f"{split}: {trajs[0].name} (red: real, green: PD only, blue: PD + residual)", weights=weights)
        print(summary_line(split, summary), flush=True)
    curves = {run_dir.name: run_dir, **{Path(c).name: Path(c) for c in compare}}
    plot_learning_curves(curves, out_dir / "fig4_learning_curves.png")
    law = {} if kappa is None else {"friction_kappa": kappa}  # the soft default's reports stay as they were
    write_report(out_dir, robot, results, {"run": str(run_dir), "residual": meta["kind"], "arch": meta["arch"],
                                           "physics": "physics.json" if physics is not None else "robot file",
                                           "solver": solver, **law, "dataset": data_label, "robot": str(robot.source)})
    print(f"wrote {out_dir / 'metrics.json'} and {out_dir / 'report.md'}")
    return results


def load_run_model(run_dir, robot, rate_hz: float, solver: str | None = None):
    """What a run folder replays: ``(policy, meta, physics, solver, substeps)``.

    ``policy`` is the run's residual (``None`` for identified physics alone), ``meta`` its ``residual.json``
    (kind, arch, joint names, rate), ``physics`` the :class:`~wresdyn.sim.physics.PhysicalParams` of
    ``physics.json`` (``None``: the robot file's), ``solver`` the one given or the run's, ``substeps`` the run's.

    Raises:
        RunError: the run was trained on other joints than ``robot``'s or at another rate than ``rate_hz`` [Hz].
    """
    import json
    from pathlib import Path

    run_dir = Path(run_dir)
    physics = run_physics(run_dir, robot)
    if physics is not None and not (run_dir / "policy.pt").exists():  # identified physics alone
        config = json.loads((run_dir / "config.json").read_text())
        policy, meta = None, {"kind": None, "arch": "none", "joint_names": physics.joint_names,
                              "rate_hz": float(config["rate_hz"])}
        solver, substeps = solver or config["solver"], 1
    else:
        policy, meta = load_policy(run_dir)
        cfg = config_from_dict(json.loads((run_dir / "config.json").read_text())["config"])
        solver, substeps = solver or cfg.env.solver, cfg.env.substeps
    if list(meta["joint_names"]) != list(robot.joint_names):
        raise RunError(f"{run_dir}: trained on joints {meta['joint_names'][:3]}..., not this robot's")
    if abs(meta["rate_hz"] - rate_hz) > 1e-9:
        raise RunError(f"{run_dir}: trained at {meta['rate_hz']:g} Hz, the data is at {rate_hz:g} Hz")
    return policy, meta, physics, solver, substeps


def run_friction_kappa(run_dir) -> float | None:
    """The replay solver's dry-friction law a run was trained with (``friction_kappa`` of its ``config.json``:
    ``None``, the soft default, for a run that records none)."""
    import json
    from pathlib import Path

    config = json.loads((Path(run_dir) / "config.json").read_text())
    if "config" not in config:  # identified physics alone
        return config.get("friction_kappa")
    return config_from_dict(config["config"]).env.friction_kappa
