"""The ablation's config (:class:`AblationConfig`): which cells to run and how long each trains, apart from the
driver (:mod:`wresdyn.experiments.ablation`) so that the command line reads it without importing torch."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

from ..choices import Arch, Learner, ResidualKind, SolverKind, check_choice, check_device, check_number, choices
from ..config_fields import set_fields
from ..errors import WresdynError
from ..fit.gradfit_config import GradFitConfig
from ..ppo.ppo_config import default_config

__all__ = ["AblationConfig"]

LEARNERS = choices(Learner)


@dataclass(frozen=True)
class AblationConfig:
    """Which cells to run and how long each trains."""

    learners: tuple[Learner, ...] = LEARNERS
    """Learners to compare."""
    archs: tuple[Arch, ...] = ("mlp", "gru")
    """Networks (ignored by ``parametric``)."""
    kinds: tuple[ResidualKind, ...] = ("torque", "delta_action")
    """Residual kinds (``parametric`` is torque only)."""
    seeds: tuple[int, ...] = (0, 1, 2)
    """Seeds per cell."""
    ppo_iterations: int = 60
    """PPO iterations per cell."""
    gradient_iterations: int = 2000
    """Gradient-fit iterations per cell (network and parametric)."""
    segments: int = 4
    """Evaluation points on each learning curve."""
    solver: SolverKind = "auto"
    """Simulation solver, the same for training and evaluation."""
    device: str = "cpu"
    """Device for simulation and networks."""
    ppo_overrides: dict = field(default_factory=dict)
    """Dotted overrides of :class:`wresdyn.ppo.ppo_config.TrainConfig` (e.g. ``{"env.num_worlds": 64}``)."""
    gradient_overrides: dict = field(default_factory=dict)
    """Overrides of :class:`wresdyn.fit.gradfit.GradFitConfig` fields (e.g. ``{"windows": 32}``)."""

    def __post_init__(self) -> None:
        for name, literal in (("learners", Learner), ("archs", Arch), ("kinds", ResidualKind)):
            values = getattr(self, name)
            if isinstance(values, str) or not values:
                raise WresdynError(f"ablation {name} = {values!r}: give a non-empty list")
            for v in values:
                check_choice(v, literal, f"ablation {name}")
        if not self.seeds:
            raise WresdynError("ablation seeds: give at least one seed")
        for seed in self.seeds:
            check_number(seed, "ablation seeds", integer=True, ge=0)
        check_number(self.segments, "ablation segments", integer=True, ge=1)
        # every segment trains at least one iteration: the first evaluation point is after segment 1
        if "ppo" in self.learners:
            check_number(self.ppo_iterations, "ablation ppo_iterations", integer=True, ge=self.segments)
        if {"gradient", "parametric"} & set(self.learners):
            check_number(self.gradient_iterations, "ablation gradient_iterations", integer=True, ge=self.segments)
        check_choice(self.solver, SolverKind, "ablation solver")
        check_device(self.device, "ablation device")
        self._check_overrides()

    def _check_overrides(self) -> None:
        """A typo in an override fails here, not after hours of other cells."""
        if self.ppo_overrides and "ppo" in self.learners:
            for arch in self.archs:  # a GRU batches by world: fewer worlds can be too few for the mini-batches
                try:
                    set_fields(default_config(), {**self.ppo_overrides, "residual.arch": arch})
                except (TypeError, WresdynError) as e:
                    raise WresdynError(f"ablation ppo_overrides: {e}") from None
        if self.gradient_overrides and {"gradient", "parametric"} & set(self.learners):
            try:
                dataclasses.replace(GradFitConfig(), **self.gradient_overrides)
            except (TypeError, WresdynError) as e:
                raise WresdynError(f"ablation gradient_overrides: {e}") from None
