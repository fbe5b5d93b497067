"""Evaluate a run folder (PPO or gradient fit) and write its report: what ``wresdyn eval RUN`` does."""

from __future__ import annotations

from ..learn.run_residual import MeanResidual, load_policy
from ..learn.runs import RunError, run_physics
from ..ppo.ppo_config import config_from_dict
from ..robot.physical import PhysicalParams
from ..sim.warmup import compile_kernels
from .open_loop import evaluate_splits, summary_line, write_report
from .plots import plot_fig3, plot_learning_curves

__all__ = ["evaluate_run", "load_run_model", "load_ensemble", "run_friction_kappa"]


def evaluate_run(run: str, ds, robot, splits=("validation", "heldout", "ood"), out: str | None = None, solver: str | None = None,
                 device: str = "cpu", joints: int = 6, compare=(), data_label: str = "", mark=None,
                 ensemble=(), draw=None, residual=None) -> dict:
    """Evaluate the exported residual of ``run`` on ``splits`` of ``ds`` and write the report; returns the
    per-split summaries. A run with ``physics.json`` (``wresdyn identify``, or a residual fitted on top of
    identified physics) replays its model with those parameters; a run with no residual evaluates the
    calibrated model under PD alone. Every replay runs under the run's own dry-friction law
    (:func:`run_friction_kappa`). ``mark``: called with a short note as each part ends (the model loaded, the splits
    replayed), for a clocked log; ``None``: nothing. ``ensemble``: other run folders whose residuals are averaged
    with ``run``'s at every step (:func:`load_ensemble`); ``()``: ``run``'s residual alone. ``draw``: called as
    ``draw(path, function, *args, **kwargs)`` for each figure (``function`` writes ``path``), with picklable copies
    of what it plots (:func:`_plotted`), e.g. to draw them in another process; ``None``: drawn here, in order.
    ``residual``: the run's residual in memory (the module its ``policy.pt`` is being exported from, e.g. by another
    process), replayed instead of reading ``policy.pt``; ``None``: read from ``policy.pt``."""
    import json
    from pathlib import Path

    import torch

    torch.set_num_threads(1)
    run_dir = Path(run)
    if ensemble:
        policy, meta, physics, solver, substeps = load_ensemble([run_dir, *ensemble], robot, ds.rate_hz, solver)
    else:
        policy, meta, physics, solver, substeps = load_run_model(run_dir, robot, ds.rate_hz, solver, residual)
    kappa = run_friction_kappa(run_dir)
    out_dir = Path(out) if out else run_dir / "eval"

    compile_kernels(robot, ds.rate_hz, ("forward",), solver=solver, device=device)
    mark = mark or (lambda _: None)
    curves = {run_dir.name: run_dir, **{Path(c).name: Path(c) for c in compare}}
    fig4 = out_dir / "fig4_learning_curves.png"
    figures = [fig4.name]
    mark("evaluation: the model loaded")
    if draw is not None:  # from the run's files only: drawn elsewhere while the splits replay
        draw(fig4, plot_learning_curves, curves, fig4)
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
        figures.append(f"fig3_{split}.png")
        path = out_dir / figures[-1]
        title = f"{split}: {trajs[0].name} (red: real, green: PD only, blue: PD + residual)"
        if draw is None:
            plot_fig3(robot, trajs[0], runs, path, ds.rate_hz, joints, title=title, weights=weights)
        else:
            draw(path, plot_fig3, *_plotted(robot, trajs[0], runs), path, ds.rate_hz, joints, title=title,
                 weights=weights)
        print(summary_line(split, summary), flush=True)
    if draw is None:
        plot_learning_curves(curves, fig4)
    law = {} if kappa is None else {"friction_kappa": kappa}  # the soft default's reports stay as they were
    members = {"ensemble": [str(r) for r in ensemble]} if ensemble else {}
    write_report(out_dir, robot, results, {"run": str(run_dir), **members, "residual": meta["kind"],
                                           "arch": meta["arch"],
                                           "physics": "physics.json" if physics is not None else "robot file",
                                           "solver": solver, **law, "dataset": data_label, "robot": str(robot.source)},
                 figures=figures)
    print(f"wrote {out_dir / 'metrics.json'} and {out_dir / 'report.md'}")
    return results


def _plotted(robot, traj, runs):
    """What :func:`~wresdyn.evaluation.plots.plot_fig3` reads of its robot, trajectory and replays: ``(robot, traj,
    runs)`` as light, picklable copies (joint names; the recording's ``q`` and name; each replay's first ``q``)."""
    from types import SimpleNamespace

    return (SimpleNamespace(joint_names=list(robot.joint_names)), SimpleNamespace(q=traj.q, name=traj.name),
            {k: SimpleNamespace(q=r.q[:1]) for k, r in runs.items()})


def load_run_model(run_dir, robot, rate_hz: float, solver: str | None = None, residual=None):
    """What a run folder replays: ``(policy, meta, physics, solver, substeps)``.

    ``policy`` is the run's residual (``None`` for identified physics alone; ``residual`` where given: the module
    its ``policy.pt`` holds, in memory), ``meta`` its ``residual.json``
    (kind, arch, joint names, rate), ``physics`` the :class:`~wresdyn.sim.physics.PhysicalParams` of
    ``physics.json`` (``None``: the robot file's), ``solver`` the one given or the run's, ``substeps`` the run's.

    Raises:
        RunError: the run was trained on other joints than ``robot``'s or at another rate than ``rate_hz`` [Hz].
    """
    import json
    from pathlib import Path

    run_dir = Path(run_dir)
    physics = run_physics(run_dir, robot)
    if residual is None and physics is not None and not (run_dir / "policy.pt").exists():  # physics alone
        config = json.loads((run_dir / "config.json").read_text())
        policy, meta = None, {"kind": None, "arch": "none", "joint_names": physics.joint_names,
                              "rate_hz": float(config["rate_hz"])}
        solver, substeps = solver or config["solver"], 1
    else:
        policy, meta = (load_policy(run_dir) if residual is None
                        else (residual, json.loads((run_dir / "residual.json").read_text())))
        cfg = config_from_dict(json.loads((run_dir / "config.json").read_text())["config"])
        solver, substeps = solver or cfg.env.solver, cfg.env.substeps
    if list(meta["joint_names"]) != list(robot.joint_names):
        raise RunError(f"{run_dir}: trained on joints {meta['joint_names'][:3]}..., not this robot's")
    if abs(meta["rate_hz"] - rate_hz) > 1e-9:
        raise RunError(f"{run_dir}: trained at {meta['rate_hz']:g} Hz, the data is at {rate_hz:g} Hz")
    return policy, meta, physics, solver, substeps


def load_ensemble(run_dirs, robot, rate_hz: float, solver: str | None = None):
    """:func:`load_run_model` of a seed ensemble of ``run_dirs``, as one model: residuals fitted on one identified
    model are averaged at every step (:class:`~wresdyn.learn.run_residual.MeanResidual`) on that model; runs of
    identified physics alone give their parameters' mean (:meth:`~wresdyn.robot.physical.PhysicalParams.mean`). The
    first run's meta, solver and substeps.

    Raises:
        RunError: the runs mix residuals and physics alone; or residuals' physics, kind, solver, substeps or
            dry-friction law differ from the first run's (members must be fits on one model); or runs of physics
            alone differ in their solver or friction law.
    """
    from pathlib import Path

    loaded = [load_run_model(r, robot, rate_hz, solver) for r in run_dirs]
    kappas = [run_friction_kappa(r) for r in run_dirs]
    first, name = loaded[0], Path(run_dirs[0])
    if len({p is None for p, *_ in loaded}) != 1:
        raise RunError(f"{name}: an ensemble averages residuals or identified physics, not both")
    for r, (policy, meta, physics, s, sub), kappa in zip(run_dirs, loaded, kappas):
        if (meta["kind"], s, sub, kappa) != (first[1]["kind"], first[3], first[4], kappas[0]):
            raise RunError(f"{r}: residual kind, solver, substeps or friction law differ from {name}'s")
        if policy is not None and _physics_json(physics) != _physics_json(first[2]):
            raise RunError(f"{r}: its physics.json differs from {name}'s")
    if first[0] is None:
        return None, first[1], PhysicalParams.mean(p for _, _, p, *_ in loaded), *first[3:]
    return MeanResidual(p for p, *_ in loaded), *first[1:]


def _physics_json(physics) -> dict | None:
    return None if physics is None else physics.to_json()


def run_friction_kappa(run_dir) -> float | None:
    """The replay solver's dry-friction law a run was trained with (``friction_kappa`` of its ``config.json``:
    ``None``, the soft default, for a run that records none)."""
    import json
    from pathlib import Path

    config = json.loads((Path(run_dir) / "config.json").read_text())
    if "config" not in config:  # identified physics alone
        return config.get("friction_kappa")
    return config_from_dict(config["config"]).env.friction_kappa
