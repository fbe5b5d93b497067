"""Fields of a frozen config dataclass by their dotted names (``"ppo.seed"``): read one (:func:`get_field`), set
several at once (:func:`set_fields`), or parse ``SECTION.FIELD=VALUE`` overrides (:func:`apply_overrides`, as
``wresdyn train --set`` takes them). Any config of the package: a leaf that imports nothing of it, so the command
line and every config use it without going through one learner's config.
"""

from __future__ import annotations

from dataclasses import fields, is_dataclass, replace

__all__ = ["get_field", "set_fields", "set_field", "parse_overrides", "apply_overrides"]


def get_field(cfg, dotted: str):
    """The value of the nested field at ``dotted`` (e.g. ``"ppo.seed"``) of ``cfg``."""
    for part in dotted.split("."):
        cfg = getattr(cfg, part)
    return cfg


def parse_overrides(cfg, items) -> dict:
    """``SECTION.FIELD=VALUE`` items (as on ``wresdyn train --set``) as ``{"SECTION.FIELD": value}``.

    SECTION is a field of ``cfg`` that is itself a config (``env``, ``residual``, ``rewards``, ``ppo`` of
    :class:`~wresdyn.ppo.ppo_config.TrainConfig`); VALUE is parsed as the field's type in ``cfg``
    (tuples as comma-separated numbers, booleans as true/false); a later item for the same field wins. Raises
    ``ValueError`` with a one-line message for an unknown key or a value of the wrong type.
    """
    sections = {f.name: getattr(cfg, f.name) for f in fields(cfg)}
    out = {}
    for item in items:
        key, sep, text = str(item).partition("=")
        section, dot, name = key.strip().partition(".")
        if not sep or not dot:
            raise ValueError(f"override {item!r} is not SECTION.FIELD=VALUE (sections: {', '.join(sections)})")
        if section not in sections:
            raise ValueError(f"override {item!r}: unknown section {section!r}; choose from {', '.join(sections)}")
        names = [f.name for f in fields(sections[section])]
        if name not in names:
            raise ValueError(f"override {item!r}: {section} has no field {name!r}; fields: {', '.join(names)}")
        current = getattr(sections[section], name)
        if current is None:  # an optional field at its None default: parse as its annotation's other type
            current = _optional_example(type(sections[section]), name)
        out[f"{section}.{name}"] = _parse_like(current, text.strip(), item)
    return out


def _optional_example(cls, name: str):
    """A value of the non-None type of field ``name`` of dataclass ``cls`` (annotated ``X | None``), to parse as."""
    hint = next(str(f.type) for f in fields(cls) if f.name == name)  # a string: config modules postpone annotations
    kind = next(t.strip() for t in hint.split("|") if t.strip() != "None")
    return {"int": 0, "float": 0.0, "bool": False}.get(kind, "")


def apply_overrides(cfg, items):
    """``cfg`` with ``SECTION.FIELD=VALUE`` overrides applied, as on ``wresdyn train --set`` (see
    :func:`parse_overrides`); a value the config refuses (:class:`~wresdyn.errors.WresdynError`) is a
    ``ValueError`` too."""
    return set_fields(cfg, parse_overrides(cfg, items))


def set_fields(cfg, values: dict):
    """``cfg`` (a frozen dataclass) with the nested fields ``{"ppo.seed": 1, ...}`` set, all at once: each
    config is rebuilt once, so checks across fields (:class:`~wresdyn.ppo.ppo_config.TrainConfig`'s mini-batch
    check) see the final values whatever the order. Unknown fields raise ``TypeError``, refused values
    :class:`~wresdyn.errors.WresdynError`."""
    direct, nested = {}, {}
    for dotted, value in values.items():
        head, _, rest = dotted.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            direct[head] = value
    for head, sub in nested.items():
        if not hasattr(cfg, head) or not is_dataclass(getattr(cfg, head)):
            raise TypeError(f"{type(cfg).__name__} has no section {head!r}")
        direct[head] = set_fields(getattr(cfg, head), sub)
    return replace(cfg, **direct)


def set_field(cfg, dotted: str, value):
    """``cfg`` (a frozen dataclass) with the nested field at ``dotted`` (e.g. ``"ppo.seed"``) set to ``value``."""
    return set_fields(cfg, {dotted: value})


def _parse_like(current, text: str, item):
    """``text`` parsed as the type of ``current`` (bool, int, float, str, tuple of numbers)."""
    try:
        if isinstance(current, bool):
            if text.lower() not in ("true", "false", "1", "0"):
                raise ValueError
            return text.lower() in ("true", "1")
        if isinstance(current, tuple):
            kind = type(current[0]) if current else float
            return tuple(kind(v) for v in text.split(",") if v.strip())
        return type(current)(text)
    except ValueError:
        raise ValueError(f"override {item!r}: {text!r} is not a {type(current).__name__}") from None
