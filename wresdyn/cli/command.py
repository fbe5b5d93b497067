"""A subcommand is a frozen dataclass read from the command line by ``tyro``: one flag per field.

Every subcommand's class derives from :class:`Command` (the options all commands share) and nests the config
dataclasses it runs on, so a setting is written down once, in its config: the flag is the field's name in kebab
case, a nested config's fields are reached by their dotted name (``--residual.kind``, ``--ppo.desired-kl``,
``--identify.iterations``), a config nested with :data:`FLAT` puts its fields at the top (``--horizon-curriculum``),
the help is the field's docstring and the default the dataclass's. Tuples are space-separated lists
(``--seeds 0 1 2``, ``--frames`` with no value for the empty list), booleans ``--x``/``--no-x``, ``None`` is
``None``.

:func:`parse` reads one command's arguments: a parse error or a value the configs' own checks (``__post_init__``)
refuse is one line, ``wresdyn CMD: error: ...``, and exit status 2, as every other user error.

This module imports tyro and the configs only (numpy at most): ``wresdyn CMD --help`` stays fast.
"""

from __future__ import annotations

import ast
import contextlib
import dataclasses
import functools
import inspect
import io
import os
import re
import sys
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated

import tyro
from tyro.constructors import ConstructorRegistry, UnsupportedTypeAnnotationError
from tyro.constructors._struct_spec_dataclass import dataclass_rule

__all__ = ["Command", "FLAT", "parse", "hidden_fields", "list_flags", "CommandLineError", "ConfigRefused"]

_typeguard_is_instance = tyro._resolver.is_instance


def _is_instance(typ, value) -> bool:
    """tyro's check that a field's default matches its annotation (a warning if not), without typeguard for the
    annotations of the configs (``X | None``, ``tuple[X, ...]``, literals): importing typeguard costs about 0.4 s of
    every ``--help``. Any other annotation goes to tyro's own check."""
    origin = typing.get_origin(typ)
    if typ is type(None):
        return value is None
    if origin is types.UnionType:
        return any(_is_instance(a, value) for a in typing.get_args(typ))
    if origin is tuple:
        if not isinstance(value, tuple):
            return False
        args = typing.get_args(typ)
        if len(args) == 2 and args[1] is Ellipsis:
            return all(_is_instance(args[0], v) for v in value)
        return len(args) == len(value) and all(_is_instance(a, v) for a, v in zip(args, value))
    return _typeguard_is_instance(typ, value)


tyro._resolver.is_instance = _is_instance

FLAT = tyro.conf.arg(name="")
"""Marker (``Annotated[Config, FLAT]``) of a nested config whose flags carry no prefix."""

PackagePath = Annotated[tuple[str, ...], tyro.conf.UseAppendAction, tyro.conf.arg(metavar="DIR")]


@dataclass(frozen=True)
class Command:
    """What every subcommand takes."""

    package_path: PackagePath = field(default=(), kw_only=True)
    """Folder holding ROS packages that a URDF's package://NAME/... mesh URIs name (repeatable, or several joined
    by the path separator); searched before the URDF's own folder tree and ROS_PACKAGE_PATH."""


class CommandLineError(Exception):
    """The command line could not be read: one line, exit status 2."""


class ConfigRefused(ValueError):
    """A config's own checks refused a value given on the command line: one line, exit status 2."""


_ROLE = re.compile(r":[a-z]+:`(~?)([^`]+)`")


def plain_help(doc: str | None) -> str | None:
    """A docstring as one paragraph of ``--help``: reST roles and literals as plain text (tyro would keep the
    docstring's line breaks inside its own wrapping)."""
    if not doc:
        return doc
    text = " ".join(doc.split())
    text = _ROLE.sub(lambda m: m.group(2).rsplit(".", 1)[-1] if m.group(1) else m.group(2), text)
    return text.replace("``", "")


@functools.lru_cache(maxsize=None)
def _module_tree(module_name: str) -> ast.Module | None:
    path = getattr(sys.modules.get(module_name), "__file__", None)
    try:
        return ast.parse(Path(path).read_text()) if path else None
    except (OSError, SyntaxError):
        return None


@functools.lru_cache(maxsize=None)
def field_docs(cls) -> dict[str, str]:
    """``{field: docstring}`` of a dataclass and its bases: the string literal right under each annotated field,
    read once per module with :mod:`ast` (tyro's own reader parses the source again for every class: a quarter of
    a second of ``wresdyn fit --help``)."""
    docs: dict[str, str] = {}
    for klass in reversed(cls.__mro__):
        tree = _module_tree(klass.__module__)
        node = next((n for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.name == klass.__name__),
                    None) if tree else None
        for a, b in zip(node.body, node.body[1:]) if node else ():
            if (isinstance(a, ast.AnnAssign) and isinstance(a.target, ast.Name) and isinstance(b, ast.Expr)
                    and isinstance(b.value, ast.Constant) and isinstance(b.value.value, str)):
                docs[a.target.id] = inspect.cleandoc(b.value.value)
    return docs


def _helptext(f, docs: dict[str, str]):
    if f.name in docs:
        return dataclasses.replace(f, helptext=plain_help(docs[f.name]))
    text = f.helptext
    return dataclasses.replace(f, helptext=(lambda: plain_help(text())) if callable(text) else plain_help(text))


def hidden_fields(hide: dict[type, tuple[str, ...]] | None = None) -> ConstructorRegistry:
    """The tyro registry of a command: the named fields of these config classes kept off the command line (at the
    default the command starts from, which it may then set itself), config fields of type ``dict`` too (they have
    no command-line form), and every help a plain paragraph (:func:`plain_help`)."""
    hide = hide or {}
    registry = ConstructorRegistry()

    @registry.primitive_rule
    def _no_dict(info):
        if info.type is dict:
            return UnsupportedTypeAnnotationError(("a dict has no command-line form",))
        return None

    @registry.struct_rule
    def _config(info):
        if not dataclasses.is_dataclass(info.type):
            return None
        spec = dataclass_rule(info)
        if spec is None:
            return None
        names = hide.get(info.type, ())
        keep = tuple(dataclasses.replace(f, type=Annotated[f.type, tyro.conf.Suppress]) if f.name in names else f
                     for f in spec.fields)
        docs = field_docs(info.type)
        return dataclasses.replace(spec, fields=tuple(_helptext(f, docs) for f in keep))

    return registry


_SEPARATOR = re.compile(r"^[─\-\s]*$")
_CHOICES = re.compile(r"Expected one of \((.*)\)\.?")
_REFUSED = re.compile(r"^Error parsing ([^-\s][^:]*): (.*)$")


def _message(text: str) -> str:
    """tyro's error (framed on a terminal, plain elsewhere) as one line: the first line of its message (two when the
    first ends in a colon), after its title."""
    lines = [line.strip().strip("│╭╮╰╯").strip() for line in text.splitlines()]
    lines = lines[next((i for i, line in enumerate(lines) if line), len(lines)):]
    if not lines:
        return "could not read the command line"
    title, body = lines[0].strip("─- "), []
    for line in lines[1:]:
        if _SEPARATOR.match(line):
            if body:
                break
            continue
        body.append(line)
    if not body:
        return title
    message = " ".join(body[:2]) if body[0].endswith(":") and len(body) > 1 else body[0]
    message = _CHOICES.sub(lambda m: "choose from " + ",".join(x.strip(" '\"") for x in m.group(1).split(",")),
                           message)
    return message if title.lower() in ("value error", "invalid choice") or title in message else \
        f"{title.lower()}: {message}"


def parse(cls, args: list[str], prog: str, description: str | None = None, default=None,
          registry: ConstructorRegistry | None = None):
    """``cls`` (a :class:`Command` dataclass) read from ``args``; ``default`` is the instance the command starts
    from (the class's defaults when ``None``). ``--help`` prints and exits 0.

    Raises:
        CommandLineError: a malformed argument (one line).
        ConfigRefused: a value a config's own checks refuse (one line).
    """
    kw = dict(args=args, prog=prog, description=description, registry=registry or hidden_fields(),
              config=(tyro.conf.SuppressFixed,), **({} if default is None else {"default": default}))
    try:
        with contextlib.redirect_stderr(io.StringIO()):
            return tyro.cli(cls, **kw)
    except SystemExit as e:
        if not e.code:
            raise
    except (ValueError, TypeError) as e:  # a config's __post_init__ refused a value (WresdynError is a ValueError)
        raise ConfigRefused(str(e).splitlines()[0] if str(e) else type(e).__name__) from None
    # again, unwrapped (tyro wraps its message to the terminal's width), to read the message in one line
    wide, old = io.StringIO(), os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "1000"
    try:
        with contextlib.redirect_stderr(wide):
            tyro.cli(cls, **kw)
    except SystemExit:
        pass
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old
    message = _message(wide.getvalue())
    refused = _REFUSED.match(message)  # a nested config's __post_init__, reported by tyro as a parse error
    if refused:
        raise ConfigRefused(refused.group(2))
    raise CommandLineError(message)


_POSITIONAL = typing.get_args(tyro.conf.Positional[int])[1:]


def _positional(hint) -> bool:
    return any(m in _POSITIONAL for m in getattr(hint, "__metadata__", ()))


def _flat(hint) -> bool:
    return any(getattr(m, "name", None) == "" for m in getattr(hint, "__metadata__", ()))


def _strip(hint):
    while typing.get_origin(hint) is Annotated:
        hint = typing.get_args(hint)[0]
    return hint


def list_flags(cls, hide: dict[type, tuple[str, ...]] | None = None, prefix: str = "") -> dict[str, object]:
    """``{flag: annotation}`` of every field of the dataclass ``cls`` as tyro spells it (nested configs by their
    dotted prefix, :data:`FLAT` ones without), but the ``hide`` ones (as :func:`hidden_fields`), dicts and
    positional arguments."""
    hide = hide or {}
    hints = typing.get_type_hints(cls, include_extras=True)
    out = {}
    for f in dataclasses.fields(cls):
        hint = hints[f.name]
        tp = _strip(hint)
        if f.name in hide.get(cls, ()) or tp is dict or _positional(hint):
            continue
        if dataclasses.is_dataclass(tp):
            out |= list_flags(tp, hide, prefix if _flat(hint) else f"{prefix}{f.name.replace('_', '-')}.")
        else:
            out[f"--{prefix}{f.name.replace('_', '-')}"] = tp
    return out
