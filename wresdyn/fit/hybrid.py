"""The hybrid model, the default of ``wresdyn fit``: identified physics with a residual network learned on top.

Stage 1 identifies the simulator's own physical parameters (:func:`wresdyn.identify.sysid.identify`, grey box) into
``OUT/identify/``; stage 2 learns the residual network by the gradient fit (:func:`wresdyn.fit.gradfit.fit`)
on the calibrated model, into ``OUT/``. Both stages checkpoint and resume, both select on validation, and the
residual's starting point (zero residual: the identified model alone) is one of its candidates, so the hybrid
is never selected worse than the model it starts from.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, replace
from pathlib import Path

from ..identify.sysid import identify
from ..learn.schedule import describe_length
from ..sim.warmup import compile_kernels
from .gradfit import fit

__all__ = ["fit_hybrid", "HybridFit", "save_identify_config"]


@dataclass(frozen=True)
class HybridFit:
    """What :func:`fit_hybrid` returns."""

    physics: object
    """The identified :class:`~wresdyn.sim.physics.PhysicalParams` (stage 1), which stage 2 ran on."""
    policy: object
    """The selected residual (:class:`~wresdyn.learn.residual.ResidualPolicy`)."""
    curve: list
    """Stage 2's learning curve rows."""
    config: object
    """The stage-2 :class:`~wresdyn.fit.gradfit.GradFitConfig` actually run."""
    identify_wall: float
    """Stage 1's training wall-clock [s]."""


def save_identify_config(out: str | Path, cfg, rate_hz: float, data_path=None) -> None:
    """``config.json`` of an identification run (read by ``wresdyn eval``)."""
    Path(out, "config.json").write_text(json.dumps({"learner": "identify", "rate_hz": rate_hz, "solver": cfg.solver,
                                                     "friction_kappa": cfg.friction_kappa, "sysid": asdict(cfg),
                                                     "data_path": str(data_path)}, indent=2))


def fit_hybrid(robot, dataset, sysid_cfg, fit_cfg, out: str | Path, data_path=None,
               log=print) -> HybridFit:
    """Identify the physics, then fit the residual on top.

    Args:
        robot, dataset: As for :func:`~wresdyn.fit.gradfit.fit`.
        sysid_cfg: :class:`~wresdyn.identify.sysid.SysIdConfig` of stage 1.
        fit_cfg: :class:`~wresdyn.fit.gradfit.GradFitConfig` of stage 2 (a network; its ``physics`` record is set
            here).
        out: Run folder; stage 1 lives in ``out/identify``.
        data_path: Where the dataset was read from (recorded in the run's config).
    """
    out = Path(out)
    id_dir = out / "identify"
    id_dir.mkdir(parents=True, exist_ok=True)
    log(f"stage 1/2: identifying {', '.join(sysid_cfg.fit)} ({describe_length(sysid_cfg)}) -> {id_dir}")
    params, id_curve = identify(robot, dataset, sysid_cfg, out=id_dir, log=log)
    save_identify_config(id_dir, sysid_cfg, dataset.rate_hz, data_path)
    cfg = replace(fit_cfg, model="network", physics=str(id_dir / "physics.json"))
    compile_kernels(robot, dataset.rate_hz, ("forward", "grad"), solver=cfg.solver, device=cfg.device, say=log)
    log(f"stage 2/2: {cfg.residual.kind} residual ({cfg.residual.arch}) on the identified model "
        f"({describe_length(cfg)})")
    policy, curve = fit(robot, dataset, cfg, out=out, log=log, physics=params)
    return HybridFit(params, policy, curve, cfg, id_curve[-1]["wall"] if id_curve else 0.0)
