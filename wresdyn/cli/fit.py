"""``wresdyn fit DATA``: learn a residual by gradient descent through the differentiable simulation.

The run folder has the same layout as a ``wresdyn train`` (PPO) run: ``config.json``, ``checkpoint.pt``
(resumed when present), ``curve.json``, and the exported residual ``policy.pt`` (a ``torch.export`` archive),
``policy.onnx`` and ``residual.json``, so ``wresdyn eval RUN`` evaluates either kind of run identically. Every line
printed is also in ``fit.log``; on a terminal a progress bar shows the elapsed and remaining time
(:mod:`wresdyn.progress`), ``--quiet`` prints nothing.
``--model hybrid`` (the default) first identifies the simulator's own physics (``wresdyn identify``, into
``OUT/identify/``, with its ``identifiability.json``: what the data can identify) and learns the residual network on
top of it (:mod:`wresdyn.fit.hybrid`); with ``--physics``
the given physics is used instead of identifying. ``--model network`` learns the residual on the robot file's
physics (the residual alone, nothing identified). ``--model parametric`` fits the residual-torque baseline
(per-joint gains, damping, friction, armature as an extra torque) and writes its parameters to ``parameters.json``.
"""

from __future__ import annotations

import gc
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager, nullcontext
from dataclasses import dataclass, field, replace
from typing import Annotated

import tyro

from ..choices import FitModel
from ..fit.gradfit_config import GradFitConfig
from ..identify.sysid_config import SysIdConfig
from .clock import ClockLog
from .command import FLAT, Command
from .fit_tail import Helper

IDENTIFY_SHARED = ("device", "seed", "solver", "friction_kappa")
"""Fields of the hybrid's identification (``--identify.*``) that are the fit's own: both stages run alike."""


@dataclass(frozen=True)
class Fit(Command):
    """``wresdyn fit``: the dataset, the run folder, the model, the gradient fit's config (its fields as flags at
    the top, ``--horizon-curriculum``) and the hybrid's identification (``--identify.*``, as ``wresdyn identify``;
    device, seed, solver and friction law are the fit's, ``--windows`` too unless ``--identify.windows`` is
    given)."""

    data: Annotated[str, tyro.conf.Positional, tyro.conf.arg(metavar="DATA")]
    """Dataset file (.npz from `wresdyn collect`)."""
    out: str = "runs/fit"
    """Run folder; an existing checkpoint is resumed."""
    robot: str | None = None
    """Robot file (default: the one the dataset was recorded on)."""
    gains: str | None = None
    """Gains config (TOML) by joint-name pattern; replaces the one stored in the dataset."""
    model: FitModel = "hybrid"
    """hybrid: identified physics + residual network; network: the residual alone; parametric: the residual-torque
    baseline."""
    eval: bool = False
    """Evaluate held-out and OOD afterwards, on the fit's device (like `wresdyn eval`)."""
    quiet: bool = False
    """Print nothing while fitting (OUT/fit.log keeps every line; the progress bar is not drawn)."""
    fit: Annotated[GradFitConfig, FLAT] = field(default_factory=GradFitConfig)
    """The gradient fit (a --horizon-curriculum without --horizon also sets the horizon to its last length)."""
    identify: SysIdConfig = field(default_factory=SysIdConfig)
    """The hybrid's identification."""

    @property
    def config(self) -> GradFitConfig:
        """The gradient fit's config: ``--model``'s (hybrid and network: a network), the horizon the curriculum's
        last length when left at its default."""
        cfg = self.fit
        given = {"model": "parametric" if self.model == "parametric" else "network"}
        if cfg.horizon_curriculum and cfg.horizon == GradFitConfig.horizon:
            given["horizon"] = cfg.horizon_curriculum[-1]
        return replace(cfg, **given)

    @property
    def identify_config(self) -> SysIdConfig:
        """The hybrid's identification on the fit's device, seed, solver and friction law, and the fit's windows
        unless ``--identify.windows`` is set."""
        cfg = self.fit
        given = {name: getattr(cfg, name) for name in IDENTIFY_SHARED}
        if self.identify.windows == SysIdConfig.windows:
            given["windows"] = cfg.windows
        return replace(self.identify, **given)


COMMAND = Fit
HIDDEN = {GradFitConfig: ("model",), SysIdConfig: IDENTIFY_SHARED}
"""Config fields without a flag of their own (the command sets them)."""


def run_beside(background, work):
    """Run ``background()`` in a thread while ``work()`` runs here; return ``work``'s result once both are done.

    ``work``'s error is raised first (after ``background`` has finished, so no file is left half written), then
    ``background``'s. For host work that shares nothing with ``work`` but the interpreter (the ONNX export beside
    the evaluation): the results are those of running them one after the other.
    """
    with ThreadPoolExecutor(1, thread_name_prefix="beside") as pool:
        done = pool.submit(background)
        result = work()
        done.result()
    return result


def onnx_with_evaluation(write_onnx, evaluate, device: str):
    """Write the ONNX file (``write_onnx()``) with the evaluation (``evaluate()``, whose result is returned): beside it
    on a thread where the evaluation replays on the CPU, after it elsewhere.

    On the CPU the replay's steps run in Warp's kernels outside the interpreter, which the export's tracing (pure
    Python) uses meanwhile. On a GPU the replay is the interpreter launching small kernels and waiting for the device
    twice a step, and each wait hands the interpreter to the export's thread, which keeps it for up to a switch
    interval: from stage 2's selection to the evaluation's end the H200 took 8.4-11.8 s with the thread, 7.3-9.6 s
    with the export before the evaluation (``benchmarks/results/speed/fitcut57_cpu/prediction.md``)."""
    if str(device).startswith("cpu"):
        return run_beside(write_onnx, evaluate)
    result = evaluate()
    write_onnx()
    return result


@contextmanager
def without_collector():
    """The cyclic garbage collector off for the block, then as it was: for work whose objects are few or short-lived
    but which the collector's passes over everything alive would slow (imports above all)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


@contextmanager
def long_lived():
    """Run a command's set-up without the cyclic garbage collector, then freeze what it left alive.

    A set-up creates objects that live as long as the process: the imported modules, the robot, and Warp's syntax
    trees of every kernel (1.2 million objects for the humanoid). Each full pass of the collector walks all of
    them: on the development CPU ten passes took 2.3 s of a fit's first 7 s as they piled up, and each later one
    0.6-1.0 s. Frozen (``gc.freeze``), they are never walked again; the set-up's cyclic garbage (about 2 % of its
    objects) is frozen with them. Collections free memory only: no result depends on when they run.
    """
    with without_collector():
        try:
            yield
        finally:
            gc.freeze()


HELPER_CORES = 4
"""Cores this process may run on from which ``--eval``'s exported residual and figures go to a helper process: it
needs a core of its own; on 2 cores shared with other work it took the fit's and made the command slower
(``benchmarks/results/speed/warm57_cpu/pairs.txt``)."""
HELPERS_CORES = 8
"""Cores from which there are three helpers (:class:`~wresdyn.cli.fit_tail.Helper`'s turns: the exported residual
alone on one, the figures in turn on the other two), so that the Fig. 3 figures drawn after the replays are drawn
side by side and beside the export."""
HELPERS_ENV = "WRESDYN_FIT_HELPERS"
"""Environment variable that sets the number of helper processes of ``--eval`` whatever the cores (0: none, the
export and figures in this process), for tests and measurements; unset: :data:`HELPER_CORES`' rule."""


def helper_count(cores: int | None = None) -> int:
    """Helper processes for ``--eval`` on ``cores`` cores (default: this process's), or as :data:`HELPERS_ENV`
    says."""
    import os

    if os.environ.get(HELPERS_ENV, "").strip():
        return max(0, int(os.environ[HELPERS_ENV]))
    if cores is None:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return 0 if cores < HELPER_CORES else 3 if cores >= HELPERS_CORES else 1


def run(args: Fit) -> int:
    with long_lived():
        cfg, identify_first, sysid, ds, robot, out, log, physics = _set_up(args)
    # with --eval the exported residual and the figures are written by helper processes (wresdyn.cli.fit_tail) that
    # import their libraries while the fit runs (started after the set-up, whose imports they would slow on a small
    # host) and write them while the evaluation replays the residual in memory
    helpers = helper_count() if args.eval else 0
    with Helper(helpers) if helpers else nullcontext() as helper:
        policy, curve, cfg, id_wall, physics = _fit(args, cfg, identify_first, sysid, ds, robot, out, log, physics)
        # the export and the evaluation import the exporters and leave a few cycles, which the command's end frees:
        # no collector passes over them on the way
        with without_collector():
            _finish(args, cfg, ds, robot, out, log, policy, curve, id_wall, physics, helper)
    return 0


def _set_up(args: Fit):
    """The fit's set-up: the data, the run's log, the physics given, the kernels and the Newton check."""
    from pathlib import Path

    from ..data.loading import load_data
    from ..fit.gradfit import fit  # noqa: F401  (torch and the learners: set-up objects too)
    from ..fit.hybrid import fit_hybrid  # noqa: F401  (the identification's modules)
    from .clock import since_start

    imported = since_start()
    cfg = args.config
    identify_first = args.model == "hybrid" and not cfg.physics
    sysid = args.identify_config if identify_first else None
    ds, robot = load_data(args.data, args.robot, args.gains)
    loaded = since_start()
    out = Path(args.out)
    what = "parametric baseline" if cfg.model == "parametric" else f"{cfg.residual.kind} residual ({cfg.residual.arch})"
    if identify_first:
        what = f"hybrid (identified physics + {what})"
    elif cfg.physics:
        what += f" on the physics of {cfg.physics}"
    # WRESDYN_LOG_CLOCK=1 stamps the lines with the seconds since the process started (where a first run's time goes)
    log = ClockLog(out / "fit.log", quiet=args.quiet)
    from ..learn.schedule import describe_length

    if log.clock:  # the start's seconds split
        log(f"start: imports {imported:.1f} s, the dataset and robot (Warp's and Newton's imports with them) "
            f"{loaded - imported:.1f} s")
    log(f"gradient fit of a {what} on {len(ds.split('train'))} trajectories of {args.data}: {describe_length(cfg)} "
        f"x {cfg.windows} windows, horizons {cfg.horizon_curriculum or (cfg.horizon,)} -> {out}")
    from ..sim.physics import PhysicalParams
    from ..sim.warmup import compile_kernels

    physics = PhysicalParams.load(cfg.physics, robot) if cfg.physics else None
    # the hybrid's stage 2 (grad) runs on stage 1's adjoint module (param_grads), whatever physics was identified
    compile_kernels(robot, ds.rate_hz, ("forward", "param_grads") if identify_first else ("forward", "grad"),
                    solver=cfg.solver, device=cfg.device, say=log)
    from ..sim.first_steps import check_newton

    # a model that blows up is refused before the long fit, from the data's first sample under its commands
    first = (ds.split("train") or ds.trajectories)[0]
    check_newton(robot, ds.rate_hz, first.q[0], first.qd[0], first.q_cmd, solver=cfg.solver, device=cfg.device,
                 physics=physics, friction_kappa=cfg.friction_kappa)
    return cfg, identify_first, sysid, ds, robot, out, log, physics


def _fit(args: Fit, cfg, identify_first, sysid, ds, robot, out, log, physics):
    """The fit itself (both stages of the hybrid): ``(policy, curve, config run, identification wall-clock or None,
    physics)``."""
    from ..fit.gradfit import fit
    from . import UserError

    try:
        if identify_first:
            from ..fit.hybrid import fit_hybrid

            hybrid = fit_hybrid(robot, ds, sysid, cfg, out, data_path=args.data, log=log)
            policy, curve, cfg, id_wall, physics = (hybrid.policy, hybrid.curve, hybrid.config, hybrid.identify_wall,
                                                    hybrid.physics)
        else:
            policy, curve = fit(robot, ds, cfg, out=out, log=log, physics=physics)
            id_wall = None
    except (ValueError, FloatingPointError) as e:
        raise UserError(str(e).splitlines()[0]) from None
    return policy, curve, cfg, id_wall, physics


def _finish(args: Fit, cfg, ds, robot, out, log, policy, curve, id_wall, physics, helper=None) -> None:
    """The run's files (export, parameters, summary) and, with ``--eval``, the evaluation; ``helper``
    (:class:`~wresdyn.cli.fit_tail.Helper`, with ``--eval``): what writes ``policy.pt``, ``policy.onnx`` and the
    figures, waited for here; ``None``: written in this process."""
    import json
    from dataclasses import asdict

    import numpy as np

    from ..fit.gradfit import export_run

    write_onnx = export_run(policy, out, cfg, ds, args.data, physics=physics, onnx_later=args.eval,
                            archive_later=helper is not None)
    if helper is not None:
        # the files of one export of the trained module, as here; the evaluation replays that module meanwhile
        _, archive, onnx = write_onnx.args
        helper.submit((archive, onnx), write_onnx.func, *write_onnx.args)
    if cfg.model == "parametric":
        params = {k: dict(zip(robot.joint_names, np.round(v, 6).tolist())) for k, v in policy.parameters_physical().items()}
        (out / "parameters.json").write_text(json.dumps(params, indent=1))
    wall = curve[-1]["wall"] if curve else 0.0
    summary = {"iterations": curve[-1]["iteration"] if curve else 0, "wall_s": wall + (id_wall or 0.0), "residual_wall_s": wall,
               "identify_wall_s": id_wall, "sim_steps": curve[-1]["sim_steps"] if curve else 0, "config": asdict(cfg)}
    (out / "train_summary.json").write_text(json.dumps(summary, indent=2))
    stages = f" (identification {id_wall:.0f} s + residual {wall:.0f} s)" if id_wall is not None else ""
    log(f"done: {summary['wall_s']:.0f} s of training{stages}, {summary['sim_steps']:.2e} simulated steps "
          f"(residual); exported {out / 'policy.pt'}")
    if args.eval:
        from ..evaluation.evaluate_run import evaluate_run

        if log.clock:
            log("evaluating the run (wresdyn eval)")
            if helper is not None:  # which way a measured run went, on stderr: the run's files stay the same
                import sys

                print(f"{helper.processes} helper process(es) write policy.pt, policy.onnx and the figures",
                      file=sys.stderr, flush=True)
        draw = residual = None
        if helper is not None:
            write_onnx, draw, residual = (lambda: None), helper.submit, policy

        def evaluate():
            # on the fit's device: its forward kernels are compiled already (a GPU fit's evaluation on the CPU would
            # wait for Clang's first compile of them)
            evaluate_run(str(out), ds, robot, data_label=str(args.data), device=cfg.device,
                         mark=log if log.clock else None, draw=draw, residual=residual)
            if log.clock:
                log("evaluation done")

        # the ONNX file (most of the export's time) is the same file from the same program whenever it is written:
        # the evaluation reads policy.pt only
        onnx_with_evaluation(write_onnx, evaluate, cfg.device)
        if helper is not None:
            helper.close()
        if log.clock:
            log(f"wrote {out / 'policy.onnx'}")
