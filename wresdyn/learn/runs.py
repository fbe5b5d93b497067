"""Run folders: checkpoints that load without unpickling, and resumes that refuse a changed configuration.

A checkpoint is a ``torch.save`` file of tensors and plain containers only (state dicts, generator states),
with everything else (iteration, curves, config, random-generator states) as JSON bytes in a uint8 tensor, so
:func:`load_checkpoint` reads it with ``torch.load(weights_only=True)``: a run folder from elsewhere can hold
data, never code.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch

from ..errors import WresdynError

__all__ = ["RunError", "config_diff", "check_resume", "save_checkpoint", "load_checkpoint"]


class RunError(WresdynError):
    """A run folder that cannot be used as asked (another config, a foreign or corrupt file, nothing to load)."""


def config_diff(old, new, prefix: str = "") -> list[str]:
    """Dotted paths where two JSON-like configs differ (both compared after a JSON round trip)."""
    old, new = json.loads(json.dumps(old)), json.loads(json.dumps(new))
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for key in sorted(set(old) | set(new)):
            path = f"{prefix}.{key}" if prefix else str(key)
            if key not in old or key not in new:
                out.append(path)
            else:
                out += config_diff(old[key], new[key], path)
        return out
    return [] if old == new else [prefix or "<root>"]


def _pick(d, path: str):
    for part in path.split("."):
        if not isinstance(d, dict) or part not in d:
            return "<absent>"
        d = d[part]
    return d


def check_resume(run_dir, old: dict, new: dict, may_change=()) -> None:
    """Raise :class:`RunError` naming the fields where ``new`` differs from the saved ``old`` config, except the
    top-level or dotted names in ``may_change``."""
    diff = [p for p in config_diff(old, new) if not any(p == m or p.startswith(m + ".") for m in may_change)]
    if diff:
        shown = ", ".join(f"{p} = {_pick(old, p)!r}, now {_pick(new, p)!r}" for p in diff[:3])
        more = f" (and {len(diff) - 3} more)" if len(diff) > 3 else ""
        raise RunError(f"{run_dir} was trained with {shown}{more}; resume with the same configuration or choose "
                       "another folder")


def save_checkpoint(path: str | Path, tensors: dict, meta: dict) -> None:
    """Write ``tensors`` (state dicts, tensors, plain containers) and JSON ``meta`` atomically to ``path``."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    blob = torch.frombuffer(bytearray(json.dumps(meta).encode("utf-8")), dtype=torch.uint8)
    tmp = path.with_suffix(path.suffix + ".tmp")
    try:
        torch.save({**tensors, "meta": blob}, tmp)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


def load_checkpoint(path: str | Path, map_location=None) -> dict:
    """Read a checkpoint written by :func:`save_checkpoint` without unpickling code; ``meta`` decoded from JSON."""
    path = Path(path)
    try:
        state = torch.load(path, map_location=map_location, weights_only=True)
        state["meta"] = json.loads(bytes(state["meta"].cpu().numpy()).decode("utf-8"))
    except Exception as e:  # torch raises many types for foreign or corrupt files
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise RunError(f"{path}: not a wresdyn checkpoint (or corrupt): {msg[:200]}") from None
    return state
