"""What the two window fits' configurations share, identification's
(:class:`~wresdyn.identify.sysid_config.SysIdConfig`) and the gradient fit's
(:class:`~wresdyn.fit.gradfit_config.GradFitConfig`): how long a fit runs (:class:`WindowFitStop`) and the checks of
the fields both have (:func:`check_window_fit_config`). Torch- and Warp-free, as the configurations themselves: the
command line reads them without building a learner."""

from __future__ import annotations

from dataclasses import dataclass

from ..choices import SolverKind, check_choice, check_device, check_friction_kappa, check_number

__all__ = ["WindowFitStop", "check_window_fit_config"]


def check_window_fit_config(cfg) -> None:
    """Checks shared by the two window fits' configs (:class:`~wresdyn.fit.gradfit_config.GradFitConfig`,
    :class:`~wresdyn.identify.sysid_config.SysIdConfig`): solver, device, sizes, schedule, seeds and loss weights."""
    check_choice(cfg.solver, SolverKind, "solver")
    check_friction_kappa(cfg.friction_kappa, "friction_kappa", cfg.solver)
    check_device(cfg.device, "device")
    for name in ("windows", "max_iterations", "patience"):
        check_number(getattr(cfg, name), name, integer=True, ge=1)
    if cfg.iterations is not None:
        check_number(cfg.iterations, "iterations", integer=True, ge=1)
    if cfg.max_seconds is not None:
        check_number(cfg.max_seconds, "max_seconds", gt=0)
    if cfg.beat_start_within is not None:
        check_number(cfg.beat_start_within, "beat_start_within", integer=True, ge=1)
    check_number(cfg.min_improvement, "min_improvement", ge=0, le=1)
    check_number(cfg.lr_decay, "lr_decay", gt=0, le=1)
    for i, h in enumerate(cfg.horizon_curriculum):
        check_number(h, f"horizon_curriculum[{i}]", integer=True, ge=1)
    check_number(cfg.seed, "seed", integer=True, ge=0)
    check_number(cfg.sim_threads, "sim_threads", integer=True, ge=1)
    for name in ("grad_truncation", "select_every", "torch_threads"):
        if getattr(cfg, name) is not None:
            check_number(getattr(cfg, name), name, integer=True, ge=1)
    for name in ("lr", "lr_final", "grad_clip"):
        check_number(getattr(cfg, name), name, gt=0)
    for name in ("w_q", "w_qd"):
        check_number(getattr(cfg, name), name, ge=0)


@dataclass(frozen=True)
class WindowFitStop:
    """How long a window fit runs (:mod:`wresdyn.learn.schedule`): a fixed count, or until validation plateaus."""

    iterations: int | None = None
    """Optimiser steps, exactly, with the horizons in equal parts and a cosine learning rate; ``None`` = until
    validation plateaus (each horizon until ``patience`` checks bring no ``min_improvement`` gain, then lower rates on
    the last horizon down to ``lr_final``), within ``max_iterations`` and ``max_seconds``."""
    patience: int = 3
    """Validation checks in a row without a ``min_improvement`` gain that end a stage; only with ``iterations``
    ``None``."""
    min_improvement: float = 0.01
    """Relative gain on the best validation error that counts as progress [-]; only with ``iterations`` ``None``."""
    lr_decay: float = 0.5
    """Factor on the learning rate at each plateau of the last horizon, down to ``lr_final``; only with
    ``iterations`` ``None``."""
    max_iterations: int = 10000
    """Ceiling on the optimiser steps when ``iterations`` is ``None`` (the log says when it stopped a fit that was
    still improving)."""
    max_seconds: float | None = None
    """Ceiling on the training wall-clock [s] when ``iterations`` is ``None``; ``None`` = none."""
    beat_start_within: int | None = None
    """Validation checks within which a fit until a plateau must beat its starting point, where the start is a
    candidate (the hybrid's residual: the identified model alone): when none of the first ``beat_start_within``
    checks scored below the start, the fit stops there and keeps the start, the result it would select if no later
    check beat it either. ``None`` = the whole schedule runs; only with ``iterations`` ``None``."""
