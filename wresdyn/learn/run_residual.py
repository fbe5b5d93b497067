"""The exported residual of a run folder, whichever learner trained it (PPO or the gradient fit): ``policy.pt`` (the
``torch.export`` archive, :mod:`.network_file`) and its ``residual.json``. Reading it imports no learner, so
``wresdyn eval``, the skills' plants and the ablation load a residual without rsl-rl's runner or the PPO trainer.

:class:`MeanResidual` averages several such residuals step by step: a seed ensemble of runs fitted on one model."""

from __future__ import annotations

import json
from pathlib import Path

import torch

from .network_file import load_residual
from .runs import RunError

__all__ = ["load_policy", "MeanResidual"]


def load_policy(run_dir: str | Path):
    """The exported residual of a run: ``(policy, meta)`` with ``policy(obs) -> residual``
    (:class:`~wresdyn.learn.network_file.ExportedResidual`, on the CPU) and ``meta`` its ``residual.json``."""
    run_dir = Path(run_dir)
    path, meta_path = run_dir / "policy.pt", run_dir / "residual.json"
    if not path.is_file() or not meta_path.is_file():
        raise RunError(f"{run_dir}: no exported residual (policy.pt, residual.json); train it first")
    return load_residual(path), json.loads(meta_path.read_text())


class MeanResidual(torch.nn.Module):
    """The mean of residuals of one kind: ``forward(obs (N, 4n)) = mean_i member_i(obs)`` [N*m or rad], (N, n).

    Every member sees the same observation and keeps its own state (a GRU's hidden), so the mean is taken of what
    each member would have done in the ensemble's replay, not of the members' own replays. ``scale``, what the
    simulator divides the residual by to record normalised actions, is the members' mean; ``obs_std`` (the unit of
    a training-time observation noise) is the first member's.
    """

    def __init__(self, members) -> None:
        super().__init__()
        members = list(members)
        if not members:
            raise ValueError("an ensemble needs at least one residual")
        kinds = {_kind(m) for m in members}
        if len(kinds) != 1:
            raise ValueError(f"residuals of different kinds cannot be averaged: {sorted(kinds)}")
        self.members = torch.nn.ModuleList(members)
        self.kind = kinds.pop()
        self.register_buffer("scale", torch.stack([torch.as_tensor(m.scale) for m in members]).mean(0))
        self.register_buffer("obs_std", torch.as_tensor(members[0].obs_std).clone())

    def residual_kind(self) -> str:
        """``"torque"`` or ``"delta_action"``."""
        return self.kind

    def reset(self) -> None:
        for m in self.members:
            if hasattr(m, "reset"):
                m.reset()

    def forward(self, obs):
        return torch.stack([m(obs) for m in self.members]).mean(0)


def _kind(policy) -> str:
    k = getattr(policy, "kind", None)
    return str(k if k is not None else policy.residual_kind())
