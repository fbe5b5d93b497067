"""Command-line flags generated from a config dataclass, so the config is the only place a setting is written down.

:func:`add_config_flags` adds one flag per field of a frozen config dataclass: ``--field-name``, and for a field
that is itself a config, ``--field.sub-field`` (the same spelling in every command that nests it). The flag's type
comes from the field's annotation (``int``, ``float``, ``str``, ``bool`` as ``--x/--no-x``, ``X | None`` with
``none`` for ``None``, tuples as comma lists, the ``Literal`` choices of :mod:`wresdyn.choices` as ``choices``), its
help from the field's docstring (the string literal under the field, read from the class source with :mod:`ast`,
as tyro reads it) and its default from the dataclass itself when ``--help`` is drawn, so neither can drift from the
code. :func:`given_fields` returns only the fields the user gave, and :func:`build_config` applies them to a base
config (``dataclasses.replace``, nested fields included); a value the config refuses is the one-line
``wresdyn CMD: error: ...``. The short spellings of earlier releases stay as aliases (``aliases``).

Nothing here imports a config's module beyond what the caller passes, so the configs must be importable without
torch or Warp: ``wresdyn CMD --help`` stays fast.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import inspect
import re
import sys
import types
import typing
from typing import Literal, get_args, get_origin, get_type_hints

from ..config_fields import set_fields

__all__ = ["add_config_flags", "given_fields", "build_config", "parse_assignments", "comma_list", "field_docs",
           "config_fields", "plain_help"]

_DEST = "config"
"""Prefix of the argparse ``dest`` of every generated flag: ``config[GROUP]:dotted.name``."""


@functools.lru_cache(maxsize=None)
def _module_tree(module_name: str) -> ast.Module | None:
    try:
        return ast.parse(inspect.getsource(sys.modules[module_name]))
    except (OSError, TypeError, KeyError):
        return None


def field_docs(cls) -> dict[str, str]:
    """``{field: docstring}`` of a dataclass and its bases: the string literal right under each annotated field."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        tree = _module_tree(klass.__module__)
        if tree is None:
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef) and node.name == klass.__name__:
                for a, b in zip(node.body, node.body[1:]):
                    if (isinstance(a, ast.AnnAssign) and isinstance(a.target, ast.Name) and isinstance(b, ast.Expr)
                            and isinstance(b.value, ast.Constant) and isinstance(b.value.value, str)):
                        docs[a.target.id] = inspect.cleandoc(b.value.value)
                break
    return docs


_ROLE = re.compile(r":[a-z]+:`(~?)([^`]+)`")


def plain_help(doc: str) -> str:
    """A docstring as one line of ``--help``: reST roles and literals as plain text, ``%`` escaped for argparse."""
    text = " ".join(doc.split())
    text = _ROLE.sub(lambda m: m.group(2).rsplit(".", 1)[-1] if m.group(1) else m.group(2), text)
    return text.replace("``", "").replace("%", "%%")


@dataclasses.dataclass(frozen=True)
class _Kind:
    """How the text of one flag becomes a field's value."""

    parse: typing.Callable[[str], object] | None
    """Text to value (``None`` for a ``--x/--no-x`` flag)."""
    metavar: str | None = None
    choices: tuple | None = None
    """argparse ``choices`` (a ``Literal`` field)."""


def _is_optional(tp) -> tuple[object, bool]:
    if get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in get_args(tp) if a is not type(None)]
        if len(args) == 1 and len(get_args(tp)) == 2:
            return args[0], True
    return tp, False


def _scalar(tp) -> tuple[typing.Callable[[str], object], str, tuple | None]:
    if get_origin(tp) is Literal:
        return str, "", tuple(get_args(tp))
    if tp is bool:
        return _bool, "BOOL", None
    if tp in (int, float, str):
        return tp, tp.__name__.upper(), None
    raise TypeError(f"no command-line form for {tp!r}")


def _bool(text: str) -> bool:
    low = text.strip().lower()
    if low not in ("true", "false", "1", "0", "yes", "no", "on", "off"):
        raise ValueError(text)
    return low in ("true", "1", "yes", "on")


def comma_list(kind, length: int | None = None, allowed: tuple | None = None):
    """argparse type: a comma-separated list of ``kind`` (empty items skipped; ``""`` is the empty tuple), of
    ``length`` items when given, each one of ``allowed`` when given; a bad list is a one-line error."""

    def parse(text: str) -> tuple:
        items = [x.strip() for x in text.split(",") if x.strip()]
        try:
            values = tuple(kind(x) for x in items)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: give a comma list of {kind.__name__} values") from None
        if allowed is not None and (not values or any(v not in allowed for v in values)):
            raise argparse.ArgumentTypeError(f"{text!r}: give a comma list from {','.join(allowed)}")
        if length is not None and len(values) != length:
            raise argparse.ArgumentTypeError(f"{text!r}: give {length} comma-separated values")
        return values

    parse.__name__ = f"comma list of {kind.__name__}"
    return parse


def _kind(tp) -> _Kind:
    tp, optional = _is_optional(tp)
    if tp is bool:
        return _Kind(None)
    if get_origin(tp) is tuple:
        args = get_args(tp)
        fixed = not (len(args) == 2 and args[1] is Ellipsis)
        item = args[0] if args else str
        kind, _, allowed = _scalar(item)
        parse = comma_list(kind, len(args) if fixed else None, allowed)
        one = ",".join(allowed) if allowed else kind.__name__.upper()
        metavar = ",".join([one] * len(args)) if fixed else f"{one},..."
        kind_ = _Kind(parse, metavar)
    else:
        kind, metavar, allowed = _scalar(tp)
        kind_ = _Kind(kind, metavar or None, allowed)
    if optional:
        inner = kind_.parse

        def parse(text: str):
            return None if text.strip().lower() == "none" else inner(text)

        parse.__name__ = getattr(inner, "__name__", "value")
        return dataclasses.replace(kind_, parse=parse, choices=kind_.choices and kind_.choices + (None,),
                                   metavar=kind_.metavar or "{" + ",".join(kind_.choices) + ",none}")
    return kind_


def _show(value) -> str:
    """A default as the user would type it."""
    if isinstance(value, tuple):
        return ",".join(str(v) for v in value) if value else "empty"
    if value is None:
        return "none"
    return str(value)


def _flag(dotted: str, negative: bool = False) -> str:
    head, _, name = dotted.rpartition(".")
    return "--" + (f"{head}." if head else "") + ("no-" if negative else "") + name.replace("_", "-")


class _Switch(argparse.Action):
    """``--x`` / ``--no-x`` (``--a.x`` / ``--a.no-x`` for a nested field): sets ``True`` / ``False``."""

    def __init__(self, option_strings, dest, negative=(), **kw):
        self.negative = tuple(negative)
        super().__init__([*option_strings, *self.negative], dest, nargs=0, **kw)

    def __call__(self, parser, namespace, values, option_string=None):
        setattr(namespace, self.dest, option_string not in self.negative)


def config_fields(cls, prefix: str = "") -> list[tuple[str, object, str]]:
    """``(dotted name, annotation, docstring)`` of every leaf field of ``cls``, nested configs flattened."""
    hints = get_type_hints(cls, vars(sys.modules[cls.__module__]))
    docs = field_docs(cls)
    out = []
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        if dataclasses.is_dataclass(tp):
            out += config_fields(tp, f"{prefix}{f.name}.")
        else:
            out.append((prefix + f.name, tp, docs.get(f.name, "")))
    return out


def _value(config, dotted: str):
    for part in dotted.split("."):
        config = getattr(config, part)
    return config


def add_config_flags(parser: argparse.ArgumentParser, defaults, *, prefix: str = "", skip=(), aliases=None,
                     variants=None, title: str | None = None) -> None:
    """One flag per field of the config ``defaults`` (an instance: its values are the defaults shown).

    Args:
        parser: Where the flags go (in an argument group titled ``title`` when given).
        defaults: The config the command starts from; :func:`build_config` applies the given flags to it.
        prefix: Put before every flag and dotted name, e.g. ``"identify."`` for a nested stage's config.
        skip: Dotted field names (without ``prefix``) the command sets itself or that have no command-line form.
        aliases: ``{dotted name: ("--old", ...)}``: more spellings of a flag, e.g. the short ones of earlier
            releases (``--residual`` for ``--residual.kind``).
        variants: ``{label: config}``: other starting configs of the command (``--floor``, ``--full``), whose
            defaults the help names where they differ.
    """
    aliases = aliases or {}
    group = parser.add_argument_group(title) if title else parser
    for dotted, tp, doc in config_fields(type(defaults)):
        if dotted in skip:
            continue
        kind = _kind(tp)
        default = _value(defaults, dotted)
        shown = [f"default: {_show(default)}"] + [f"{label}: {_show(_value(v, dotted))}"
                                                  for label, v in (variants or {}).items()
                                                  if _value(v, dotted) != default]
        flags = [_flag(prefix + dotted), *aliases.get(dotted, ())]
        kw = dict(dest=f"{_DEST}[{prefix}]:{dotted}", default=argparse.SUPPRESS,
                  help=f"{plain_help(doc)} ({'; '.join(shown)})".lstrip())
        if kind.parse is None:
            negative = [_flag(prefix + dotted, negative=True)] + [f"--no-{a[2:]}" for a in aliases.get(dotted, ())]
            group.add_argument(*flags, action=_Switch, negative=negative, **kw)
        else:
            group.add_argument(*flags, type=kind.parse, metavar=kind.metavar, choices=kind.choices, **kw)


def given_fields(args: argparse.Namespace, prefix: str = "") -> dict:
    """``{dotted name: value}`` of the flags of :func:`add_config_flags` (with this ``prefix``) the user gave."""
    head = f"{_DEST}[{prefix}]:"
    return {k[len(head):]: v for k, v in vars(args).items() if k.startswith(head)}


def build_config(base, values: dict):
    """``base`` with the nested fields ``{"ppo.seed": 1, ...}`` set at once (each config rebuilt once, so its
    checks see the final values); an unknown field or a value the config refuses is a one-line user error."""
    from . import UserError

    try:
        return set_fields(base, values)
    except (TypeError, ValueError) as e:  # WresdynError is a ValueError
        raise UserError(str(e).splitlines()[0]) from None


def parse_assignments(cls, items, flag: str = "--set") -> dict:
    """``FIELD=VALUE`` items (dotted names for nested fields, as ``--set ppo.desired_kl=0.05``) as
    ``{dotted name: value}``, each VALUE read as its flag would read it; a later item for a field wins. A malformed
    item is a one-line user error."""
    from . import UserError

    kinds = {dotted: _kind(tp) for dotted, tp, _ in config_fields(cls)}
    out = {}
    for item in items:
        key, sep, text = str(item).partition("=")
        key = key.strip()
        if not sep:
            raise UserError(f"{flag} {item!r} is not FIELD=VALUE")
        if key not in kinds:
            sections = sorted({k.split(".")[0] for k in kinds if "." in k})
            raise UserError(f"{flag} {item!r}: no field {key!r}" + (f" (sections: {', '.join(sections)})"
                                                                     if sections else ""))
        kind = kinds[key]
        try:
            value = (kind.parse or _bool)(text.strip())
        except (ValueError, argparse.ArgumentTypeError):
            raise UserError(f"{flag} {item!r}: {text.strip()!r} is not a valid value") from None
        if kind.choices is not None and value not in kind.choices:
            raise UserError(f"{flag} {item!r}: choose from {', '.join(map(str, kind.choices))}")
        out[key] = value
    return out

