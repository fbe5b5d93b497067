"""The exported residual of a run folder, whichever learner trained it (PPO or the gradient fit): ``policy.pt`` (the
``torch.export`` archive, :mod:`.network_file`) and its ``residual.json``. Reading it imports no learner, so
``wresdyn eval``, the skills' plants and the ablation load a residual without rsl-rl's runner or the PPO trainer."""

from __future__ import annotations

import json
from pathlib import Path

from .network_file import load_residual
from .runs import RunError

__all__ = ["load_policy"]


def load_policy(run_dir: str | Path):
    """The exported residual of a run: ``(policy, meta)`` with ``policy(obs) -> residual``
    (:class:`~wresdyn.learn.network_file.ExportedResidual`, on the CPU) and ``meta`` its ``residual.json``."""
    run_dir = Path(run_dir)
    path, meta_path = run_dir / "policy.pt", run_dir / "residual.json"
    if not path.is_file() or not meta_path.is_file():
        raise RunError(f"{run_dir}: no exported residual (policy.pt, residual.json); train it first")
    return load_residual(path), json.loads(meta_path.read_text())
