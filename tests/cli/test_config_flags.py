"""Flags generated from a config dataclass (wresdyn.cli.config_flags): types, help, defaults, what was given."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field
from typing import Literal

import pytest

from wresdyn.cli import UserError
from wresdyn.cli.config_flags import (add_config_flags, build_config, comma_list, field_docs, given_fields,
                                      parse_assignments, plain_help)
from wresdyn.errors import WresdynError


@dataclass(frozen=True)
class Inner:
    """A nested config."""

    width: int = 64
    """Hidden units per layer."""
    dims: tuple[int, ...] = (8, 4)
    """Layer widths."""
    normalise: bool = True
    """Normalise the input."""


@dataclass(frozen=True)
class Outer:
    """A config with one of each kind of field."""

    steps: int = 10
    """Optimiser steps, 100 % of them."""
    rate: float = 1e-3
    """Step size (see :class:`~wresdyn.identify.sysid_config.SysIdConfig`, ``lr``)."""
    kind: Literal["a", "b"] = "a"
    """Which kind."""
    scale: tuple[float, float] = (1.0, 2.0)
    """Two factors."""
    names: tuple[Literal["x", "y"], ...] = ("x",)
    """Names, a list of choices."""
    limit: int | None = None
    """A bound (``None``: none)."""
    inner: Inner = field(default_factory=Inner)
    """The nested part."""

    def __post_init__(self) -> None:
        if self.steps < 1:
            raise WresdynError(f"steps = {self.steps} must be >= 1")


def _parser(**kw) -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(exit_on_error=False)
    add_config_flags(p, Outer(), **kw)
    return p


def test_field_docstrings_are_read_from_the_source():
    docs = field_docs(Outer)
    assert docs["steps"] == "Optimiser steps, 100 % of them." and docs["inner"] == "The nested part."
    assert field_docs(Inner)["dims"] == "Layer widths."


def test_help_is_the_docstring_in_plain_text_with_the_default():
    assert plain_help(field_docs(Outer)["rate"]) == "Step size (see SysIdConfig, lr)."
    helps = {a.option_strings[0]: a.help for a in _parser()._actions if a.option_strings}
    assert helps["--steps"] == "Optimiser steps, 100 %% of them. (default: 10)"  # argparse reads %% as %
    assert helps["--scale"].endswith("(default: 1.0,2.0)") and helps["--limit"].endswith("(default: none)")
    assert helps["--inner.dims"] == "Layer widths. (default: 8,4)"
    assert "Optimiser steps, 100 % of them. (default: 10)" in " ".join(_parser().format_help().split())


def test_every_field_is_a_flag_and_only_given_ones_are_returned():
    p = _parser()
    flags = {s for a in p._actions for s in a.option_strings}
    assert {"--steps", "--rate", "--kind", "--scale", "--names", "--limit", "--inner.width", "--inner.dims",
            "--inner.normalise", "--inner.no-normalise"} <= flags
    assert given_fields(p.parse_args([])) == {}
    args = p.parse_args(["--steps", "3", "--scale", "0.5,4", "--names", "y,x", "--limit", "none", "--inner.dims",
                         "16, 8,", "--inner.no-normalise", "--kind", "b"])
    assert given_fields(args) == {"steps": 3, "scale": (0.5, 4.0), "names": ("y", "x"), "limit": None,
                                  "inner.dims": (16, 8), "inner.normalise": False, "kind": "b"}
    cfg = build_config(Outer(), given_fields(args))
    assert cfg == Outer(steps=3, scale=(0.5, 4.0), names=("y", "x"), kind="b",
                        inner=Inner(dims=(16, 8), normalise=False))
    assert given_fields(p.parse_args(["--limit", "7"]))["limit"] == 7


@pytest.mark.parametrize("argv", [["--steps", "x"], ["--kind", "c"], ["--scale", "1,2,3"], ["--names", "x,z"],
                                  ["--limit", "many"]])
def test_a_malformed_value_is_refused_by_the_parser(argv):
    with pytest.raises(argparse.ArgumentError):
        _parser().parse_args(argv)


def test_a_value_the_config_refuses_is_a_one_line_user_error():
    with pytest.raises(UserError, match=r"^steps = 0 must be >= 1$"):
        build_config(Outer(), {"steps": 0})
    with pytest.raises(UserError):
        build_config(Outer(), {"inner.depth": 2})


def test_prefix_skip_aliases_and_variants():
    p = argparse.ArgumentParser()
    add_config_flags(p, Outer(), skip=("rate",), aliases={"inner.width": ("--width",)},
                     variants={"--big": Outer(steps=99)})
    add_config_flags(p, Inner(), prefix="stage.")
    flags = {s for a in p._actions for s in a.option_strings}
    assert "--rate" not in flags and {"--width", "--stage.width", "--stage.no-normalise"} <= flags
    helps = {a.option_strings[0]: a.help for a in p._actions if a.option_strings}
    assert helps["--steps"].endswith("(default: 10; --big: 99)") and helps["--kind"].endswith("(default: a)")
    args = p.parse_args(["--width", "5", "--stage.width", "6"])
    assert given_fields(args) == {"inner.width": 5} and given_fields(args, "stage.") == {"width": 6}


def test_assignments_read_values_as_their_flags_do():
    assert parse_assignments(Outer, ["inner.dims=4,2", "steps=5", "steps=6", "inner.normalise=false"]) == {
        "inner.dims": (4, 2), "steps": 6, "inner.normalise": False}
    for bad, msg in (("steps", "not FIELD=VALUE"), ("inner.depth=2", "no field 'inner.depth'"),
                     ("steps=x", "'x' is not a valid value"), ("kind=c", "choose from a, b")):
        with pytest.raises(UserError, match=msg):
            parse_assignments(Outer, [bad])


def test_comma_list():
    assert comma_list(int)("") == () and comma_list(float, 2)("1, 2") == (1.0, 2.0)
    with pytest.raises(argparse.ArgumentTypeError, match="give 4 comma-separated values"):
        comma_list(int, 4)("1,2")
