"""``wresdyn fit DATA``: learn a residual by gradient descent through the differentiable simulation.

The run folder has the same layout as a ``wresdyn train`` (PPO) run: ``config.json``, ``checkpoint.pt``
(resumed when present), ``curve.json``, and the exported residual ``policy.pt`` (a ``torch.export`` archive),
``policy.onnx`` and ``residual.json``, so ``wresdyn eval RUN`` evaluates either kind of run identically. Every line
printed is also in ``fit.log``; on a terminal a progress bar shows the elapsed and remaining time
(:mod:`wresdyn.progress`), ``--quiet`` prints nothing.
``--model hybrid`` (the default) first identifies the simulator's own physics (``wresdyn identify``, into
``OUT/identify/``) and learns the residual network on top of it (:mod:`wresdyn.learn.hybrid`); with ``--physics``
the given physics is used instead of identifying. ``--model network`` learns the residual on the robot file's
physics (the residual alone, nothing identified). ``--model parametric`` fits the residual-torque baseline
(per-joint gains, damping, friction, armature as an extra torque) and writes its parameters to ``parameters.json``.
"""

from __future__ import annotations

import argparse

from ..choices import Arch, FitModel, ResidualKind, SolverKind, choices
from ..learn.hybrid import HYBRID_ITERATIONS
from .identify import GAIN_GRID_HELP, parse_grid



def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("data", help="dataset file (.npz from `wresdyn collect`)")
    p.add_argument("--out", default="runs/fit", help="run folder; an existing checkpoint is resumed (default: runs/fit)")
    p.add_argument("--robot", default=None, help="robot file (default: the one the dataset was recorded on)")
    p.add_argument("--gains", default=None,
                   help="gains config (TOML) by joint-name pattern; replaces the one stored in the dataset")
    p.add_argument("--model", choices=choices(FitModel), default="hybrid",
                   help="hybrid: identified physics + residual network (default); network: the residual alone; "
                        "parametric: the residual-torque baseline")
    p.add_argument("--residual", choices=choices(ResidualKind), default="torque",
                   help="torque (paper) or delta_action (ASAP)")
    p.add_argument("--arch", choices=choices(Arch), default="mlp", help="network: mlp (ELU) or gru (GRU + MLP)")
    p.add_argument("--fraction", type=float, default=None, help="residual authority, fraction of each effort limit")
    p.add_argument("--iterations", type=int, default=None,
                   help=f"optimiser steps of the residual (default {HYBRID_ITERATIONS} for hybrid, else 2000)")
    p.add_argument("--identify-iterations", type=int, default=None,
                   help="optimiser steps of the hybrid's identification (default 800, as `wresdyn identify`)")
    p.add_argument("--gain-grid", default=None, metavar="FACTORS",
                   help="the hybrid's identification: " + GAIN_GRID_HELP + "; as `wresdyn identify --gain-grid`")
    p.add_argument("--refine", type=int, default=None, metavar="STEPS",
                   help="L-BFGS steps after the hybrid's identification, as `wresdyn identify --refine` (default 0)")
    p.add_argument("--windows", type=int, default=None,
                   help="parallel windows (worlds) per step, of both hybrid stages (default 32)")
    p.add_argument("--horizon", type=int, default=None, help="final window length [steps]")
    p.add_argument("--curriculum", default=None, help="window lengths to step through, e.g. 2,4,8,16,32,64 ('' for none)")
    p.add_argument("--lr", type=float, default=None, help="initial Adam learning rate")
    p.add_argument("--obs-noise", type=float, default=None,
                   help="training noise on the network's observation, in normalising stds (0 = off)")
    p.add_argument("--solver", choices=choices(SolverKind), default=None, help="simulation solver (default: auto)")
    p.add_argument("--device", default="cpu", help="cpu or cuda:0")
    p.add_argument("--no-cuda-graph", action="store_true",
                   help="CUDA: run each iteration eagerly instead of replaying it from a CUDA graph")
    p.add_argument("--seed", type=int, default=0, help="seed")
    p.add_argument("--physics", default=None, metavar="JSON",
                   help="learn the residual on top of identified physics (physics.json of `wresdyn identify`)")
    p.add_argument("--eval", action="store_true", help="evaluate held-out and OOD afterwards (like `wresdyn eval`)")
    p.add_argument("--quiet", action="store_true",
                   help="print nothing while fitting (OUT/fit.log keeps every line; the progress bar is not drawn)")


def config_from_args(args: argparse.Namespace):
    """The default :class:`~wresdyn.learn.gradfit.GradFitConfig` with the flags applied."""
    from dataclasses import replace

    from ..learn.gradfit import GradFitConfig

    cfg = GradFitConfig()
    res = {"kind": args.residual, "arch": args.arch}
    if args.fraction is not None:
        res["fraction"] = args.fraction
    kw = {k: v for k, v in (("iterations", args.iterations), ("windows", args.windows), ("horizon", args.horizon),
                            ("lr", args.lr), ("solver", args.solver), ("obs_noise", args.obs_noise),
                            ("physics", args.physics)) if v is not None}
    if args.curriculum is not None:
        kw["horizon_curriculum"] = tuple(int(h) for h in args.curriculum.split(",") if h)
        if kw["horizon_curriculum"] and "horizon" not in kw:
            kw["horizon"] = kw["horizon_curriculum"][-1]
    if args.model == "hybrid" and args.iterations is None:
        kw["iterations"] = HYBRID_ITERATIONS
    model = "parametric" if args.model == "parametric" else "network"
    return replace(cfg, residual=replace(cfg.residual, **res), model=model, device=args.device, seed=args.seed,
                   cuda_graph=not args.no_cuda_graph, **kw)


def run(args: argparse.Namespace) -> int:
    import json
    from dataclasses import asdict, replace
    from pathlib import Path

    import numpy as np

    from ..data.loading import load_data
    from ..learn.gradfit import export_run, fit
    from . import UserError

    cfg = config_from_args(args)
    gain_grid = None if args.gain_grid is None else parse_grid(args.gain_grid, "--gain-grid", "factors on kp")
    ds, robot = load_data(args.data, args.robot, args.gains)
    out = Path(args.out)
    identify_first = args.model == "hybrid" and not cfg.physics
    what = "parametric baseline" if cfg.model == "parametric" else f"{cfg.residual.kind} residual ({cfg.residual.arch})"
    if identify_first:
        what = f"hybrid (identified physics + {what})"
    elif cfg.physics:
        what += f" on the physics of {cfg.physics}"
    from ..progress import Log

    log = Log(out / "fit.log", quiet=args.quiet)
    log(f"gradient fit of a {what} on {len(ds.split('train'))} trajectories of {args.data}: {cfg.iterations} "
          f"iterations x {cfg.windows} windows, horizons {cfg.horizon_curriculum or (cfg.horizon,)} -> {out}")
    from ..sim.physics import PhysicalParams
    from ..sim.warmup import compile_kernels

    physics = PhysicalParams.load(cfg.physics, robot) if cfg.physics else None
    # the hybrid's stage 2 runs on the identified physics: fit_hybrid compiles those kernels once stage 1 is done
    compile_kernels(robot, ds.rate_hz, ("forward", "param_grads") if identify_first else ("forward", "grad"),
                    solver=cfg.solver, device=cfg.device, physics=physics, say=log)
    try:
        if identify_first:
            from ..learn.hybrid import fit_hybrid
            from ..learn.sysid import SysIdConfig

            stage1 = {k: v for k, v in (("iterations", args.identify_iterations), ("windows", args.windows),
                                        ("refine", args.refine)) if v is not None}
            if gain_grid is not None:
                stage1["gain_grid"] = gain_grid
            sysid = replace(SysIdConfig(), device=cfg.device, seed=cfg.seed, solver=cfg.solver, **stage1)
            hybrid = fit_hybrid(robot, ds, sysid, cfg, out, data_path=args.data, log=log)
            policy, curve, cfg, id_wall, physics = (hybrid.policy, hybrid.curve, hybrid.config, hybrid.identify_wall,
                                                    hybrid.physics)
        else:
            policy, curve = fit(robot, ds, cfg, out=out, log=log, physics=physics)
            id_wall = None
    except (ValueError, FloatingPointError) as e:
        raise UserError(str(e).splitlines()[0]) from None
    export_run(policy, out, cfg, ds, args.data, physics=physics)
    if cfg.model == "parametric":
        params = {k: dict(zip(robot.joint_names, np.round(v, 6).tolist())) for k, v in policy.parameters_physical().items()}
        (out / "parameters.json").write_text(json.dumps(params, indent=1))
    wall = curve[-1]["wall"] if curve else 0.0
    summary = {"iterations": cfg.iterations, "wall_s": wall + (id_wall or 0.0), "residual_wall_s": wall,
               "identify_wall_s": id_wall, "sim_steps": curve[-1]["sim_steps"] if curve else 0, "config": asdict(cfg)}
    (out / "train_summary.json").write_text(json.dumps(summary, indent=2))
    stages = f" (identification {id_wall:.0f} s + residual {wall:.0f} s)" if id_wall is not None else ""
    log(f"done: {summary['wall_s']:.0f} s of training{stages}, {summary['sim_steps']:.2e} simulated steps "
          f"(residual); exported {out / 'policy.pt'}")
    if args.eval:
        from ..evaluation.evaluate_run import evaluate_run

        evaluate_run(str(out), ds, robot, data_label=str(args.data))
    return 0
