"""The residual's configuration (:class:`ResidualConfig`), apart from the networks of :mod:`.residual` so that the
command line reads it without importing torch."""

from __future__ import annotations

from dataclasses import dataclass

from ..choices import Arch, ResidualKind, check_choice, check_number
from ..errors import WresdynError

__all__ = ["ResidualConfig"]


@dataclass(frozen=True)
class ResidualConfig:
    """What the residual acts on and the network that produces it."""

    kind: ResidualKind = "torque"
    """One of :data:`wresdyn.sim.residual_kinds.KINDS`."""
    fraction: float = 0.5
    """Residual authority: the largest residual as a fraction of each joint's effort limit (for
    ``delta_action``, divided by kp). PPO's default 0.5, checked on validation: 0.0315 rad against 0.0352 at
    0.25 after 1200 iterations (``benchmarks/results/validation_protocol/ppo_sweep_authority_1200_summary.md``);
    the "real" drives saturate at 20 % of the limit and cancelling PD torque beyond that needs room. The
    gradient fit's default is 0.25 (:class:`wresdyn.fit.gradfit.GradFitConfig`)."""
    action_gain: float = 0.2
    """Normalised residual per unit of network output, g in clip(g · a, −1, 1); 0.2 makes one unit
    0.05 of the effort limit and the initial exploration noise (``init_std`` 1) that large."""
    arch: Arch = "mlp"
    """One of :data:`ARCHS`."""
    hidden_dims: tuple[int, ...] = (256, 128, 64)
    """Actor MLP hidden layer widths (ELU)."""
    critic_hidden_dims: tuple[int, ...] = (256, 128, 64)
    """Critic MLP hidden layer widths (ELU); the critic is an MLP for both architectures."""
    gru_hidden_dim: int = 64
    """GRU hidden state size (``arch="gru"``)."""
    gru_layers: int = 1
    """Number of stacked GRU layers."""
    init_std: float = 1.0
    """Initial exploration std of the network output (see ``action_gain``)."""
    obs_normalization: bool = True
    """Also normalise observations with running statistics of the simulated rollouts (rsl-rl's
    ``EmpiricalNormalization``, exported with the policy)."""
    output_gain: float = 0.01
    """Scale of the actor's last-layer initial weights: the residual starts near zero, i.e. at PD-only."""

    def __post_init__(self) -> None:
        check_choice(self.kind, ResidualKind, "residual.kind")
        check_choice(self.arch, Arch, "residual.arch")
        for name in ("fraction", "action_gain", "init_std"):
            check_number(getattr(self, name), f"residual.{name}", gt=0)
        check_number(self.output_gain, "residual.output_gain", ge=0)  # 0: the residual starts exactly at zero
        for name in ("gru_hidden_dim", "gru_layers"):
            check_number(getattr(self, name), f"residual.{name}", integer=True, ge=1)
        for name in ("hidden_dims", "critic_hidden_dims"):
            dims = getattr(self, name)
            if not isinstance(dims, (tuple, list)):
                raise WresdynError(f"residual.{name} = {dims!r} is not a sequence of layer widths")
            for i, d in enumerate(dims):
                check_number(d, f"residual.{name}[{i}]", integer=True, ge=1)
        if not isinstance(self.obs_normalization, bool):
            raise WresdynError(f"residual.obs_normalization = {self.obs_normalization!r} is not true or false")
