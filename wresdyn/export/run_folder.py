"""What every export of a run checks before it writes anything (USD, :mod:`.usd`; MJCF, :mod:`.mjcf`)."""

from __future__ import annotations

import json
from pathlib import Path

from ..errors import WresdynError

__all__ = ["ExportError", "open_run"]


class ExportError(WresdynError):
    """A run that cannot be exported; the message is one line."""


def open_run(run: Path, out: Path, force: bool, physics_only: bool) -> tuple[Path, dict | None]:
    """The checks every export of a run makes before writing: ``(config.json, residual.json's record or None)``."""
    cfg_path = run / "config.json"
    if not cfg_path.is_file():
        raise ExportError(f"{run}: not a run folder (no config.json)")
    if out.exists() and not force:
        raise ExportError(f"{out}: already exists; pass --force to replace it")
    has_residual = (run / "policy.pt").is_file() and (run / "residual.json").is_file()
    if not has_residual and not physics_only:
        raise ExportError(f"{run}: the run has no residual (policy.pt, residual.json); export a `wresdyn fit` run, "
                          "or pass --physics-only for the identified physics alone")
    residual = json.loads((run / "residual.json").read_text()) if has_residual and not physics_only else None
    if residual is not None and residual.get("kind") != "torque":
        raise ExportError(f"{run}: a {residual.get('kind')} residual cannot be exported yet (only torque residuals "
                          "act outside the delayed command path)")
    return cfg_path, residual
