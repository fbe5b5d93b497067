"""Two JSON-like configurations compared field by field: the dotted paths where they differ (:func:`config_diff`)
and the differences in words (:func:`describe_diff`), as a resumed run's refusal names them
(:func:`wresdyn.learn.runs.check_resume`)."""

from __future__ import annotations

import json
import math

__all__ = ["config_diff", "describe_diff", "first_difference", "plain_json"]


def plain_json(value):
    """``value`` as it reads back from ``config.json``: tuples become lists, dataclasses are already dicts."""
    return json.loads(json.dumps(value))


def _same(a, b) -> bool:
    if isinstance(a, bool) or isinstance(b, bool):
        return type(a) is type(b) and a == b  # True == 1 in Python, not in a config
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def _diff(old, new, path: str, out: list[str]) -> None:
    if isinstance(old, dict) and isinstance(new, dict):
        for key in list(old) + [k for k in new if k not in old]:
            sub = f"{path}.{key}" if path else str(key)
            if key not in old or key not in new:
                out.append(sub)
            else:
                _diff(old[key], new[key], sub, out)
    elif isinstance(old, list) and isinstance(new, list) and len(old) == len(new):
        for i, (a, b) in enumerate(zip(old, new)):
            _diff(a, b, f"{path}[{i}]", out)
    elif isinstance(old, (dict, list)) or isinstance(new, (dict, list)):
        if old != new:
            out.append(path)
    elif not _same(old, new):
        out.append(path)


def config_diff(old: dict, new: dict) -> list[str]:
    """Dotted paths at which two JSON-like configs differ, in ``old``'s key order.

    Both are compared as they read back from JSON (tuples are lists; floats exactly, after the round trip, so
    a config equals the one it wrote). Nested dicts give ``a.b.c``; lists of the same length are compared per
    element, ``a.b[2]``; a key on one side only, or a list whose length changed, gives its own path.
    """
    out: list[str] = []
    _diff(plain_json(old), plain_json(new), "", out)
    return out


def first_difference(old, new) -> tuple[str, object, object] | None:
    """The first dotted path of :func:`config_diff` with the value on each side (``"<missing>"`` where a side lacks
    it), ``None`` where the two are equal."""
    paths = config_diff(old, new)
    if not paths:
        return None
    return paths[0], _lookup(plain_json(old), paths[0]), _lookup(plain_json(new), paths[0])


def _lookup(d, path: str):
    for part in path.replace("[", ".[").split("."):
        if not isinstance(d, (dict, list)):
            return "<missing>"
        if part.startswith("["):
            d = d[int(part[1:-1])]
        elif part in d:
            d = d[part]
        else:
            return "<missing>"
    return d


def _short(value, width: int = 60) -> str:
    text = value if value == "<missing>" else json.dumps(value)
    return text if len(text) <= width else text[: width - 3] + "..."


def describe_diff(old: dict, new: dict, paths=None, limit: int = 3) -> str:
    """Differences in words, ``"ppo.gamma = 0.9, now 0.95; ..."``: those at ``paths`` (default: all of
    :func:`config_diff`), at most ``limit`` with values, then how many more; ``""`` when there are none."""
    paths = config_diff(old, new) if paths is None else list(paths)
    old, new = plain_json(old), plain_json(new)
    parts = [f"{p} = {_short(_lookup(old, p))}, now {_short(_lookup(new, p))}" for p in paths[:limit]]
    if len(paths) > limit:
        parts.append(f"and {len(paths) - limit} more ({', '.join(paths[limit:])})")
    return "; ".join(parts)
