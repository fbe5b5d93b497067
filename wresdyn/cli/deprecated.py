"""Spellings of earlier releases, rewritten to today's before the command line is parsed, each with a one-line
note naming the new spelling. They keep working for one release; then :data:`RENAMED` and this rewriting go.

What is rewritten:

- a flag renamed (:data:`RENAMED`): ``wresdyn fit --curriculum`` is ``--horizon-curriculum``;
- ``wresdyn train --set SECTION.FIELD=VALUE``: the field's own flag, ``--section.field VALUE``;
- a comma list (``--seeds 0,1,2``): a space-separated one (``--seeds 0 1 2``; ``""`` the empty list);
- ``none`` for an unset value: ``None``;
- an optional switch given bare (``deploy --oracle-beside``): ``--oracle-beside True``; its negative
  (``--ppo.no-graph-update``, a switch of old): ``--ppo.graph-update False``;
- ``--flag=VALUE``: ``--flag VALUE`` (read by both, split only to rewrite the parts).
"""

from __future__ import annotations

import types
import typing
from typing import Callable

__all__ = ["RENAMED", "rewrite"]

_RESIDUAL = {"--residual": "--residual.kind", "--arch": "--residual.arch", "--fraction": "--residual.fraction"}

RENAMED: dict[str, dict[str, str]] = {
    "fit": {**_RESIDUAL, "--curriculum": "--horizon-curriculum", "--identify-iterations": "--identify.iterations",
            "--gain-grid": "--identify.gain-grid", "--refine": "--identify.refine"},
    "train": {**_RESIDUAL, "--iterations": "--ppo.iterations", "--num-envs": "--env.num-worlds",
              "--ppo.num-envs": "--env.num-worlds",
              "--steps-per-env": "--ppo.num-steps-per-env", "--horizon": "--env.horizon",
              "--obs-noise": "--env.obs-noise", "--solver": "--env.solver", "--friction-kappa": "--env.friction-kappa",
              "--device": "--ppo.device", "--seed": "--ppo.seed", "--save-interval": "--ppo.save-interval",
              "--physics": "--env.physics"},
    "collect": {"--excitation": "--excitation.mode", "--frames": "--excitation.frames"},
    "deploy": {"--motions": "--train-per-family", "--heldout": "--heldout-per-family", "--envs": "--num-worlds",
               "--oracle-envs": "--oracle-num-worlds"},
}
"""``{command: {old flag: new flag}}``: the short spellings of earlier releases."""


def _optional(tp) -> tuple[object, bool]:
    if typing.get_origin(tp) in (typing.Union, types.UnionType):
        args = [a for a in typing.get_args(tp) if a is not type(None)]
        if len(args) == 1:
            return args[0], True
    return tp, False


def rewrite(command: str, flags: dict[str, object], argv: list[str], say: Callable[[str], None]) -> list[str]:
    """``argv`` (the arguments after the command's name) with every spelling of earlier releases replaced by
    today's, given the command's ``{flag: annotation}`` (:func:`~wresdyn.cli.command.list_flags`); ``say`` gets one
    note per replacement."""
    renamed = RENAMED.get(command, {})
    out: list[str] = []
    i = 0
    while i < len(argv):
        token = argv[i]
        i += 1
        if not token.startswith("--") or token == "--":
            out.append(token)
            continue
        flag, eq, inline = token.partition("=")
        if command == "train" and flag == "--set":
            item = inline if eq else (argv[i] if i < len(argv) else "")
            i += 0 if eq else 1
            key, sep, text = item.partition("=")
            new = "--" + key.strip().replace("_", "-")
            new = renamed.get(new, new)
            if not sep or new not in flags:
                out.append(token)  # tyro names the unknown argument
                continue
            if flags[new] is bool:  # a switch: --x or --no-x
                on = text.strip().lower() in ("true", "1", "yes", "on")
                head, _, last = new[2:].rpartition(".")
                switch = new if on else "--" + (f"{head}." if head else "") + "no-" + last
                say(f"note: --set {item} is deprecated; write {switch}")
                out.append(switch)
                continue
            value = text.strip()
            if _optional(flags[new]) == (bool, True) and value.lower() in ("true", "false", "none"):
                value = value.capitalize()  # an optional switch reads True, False or None
            say(f"note: --set {item} is deprecated; write {new} {value}")
            flag, eq, inline = new, "=", value
        elif flag in renamed:
            say(f"note: {flag} is deprecated; write {renamed[flag]}")
            flag = renamed[flag]
        elif flag.startswith("--no-") and f"--{flag[5:]}" in renamed:  # the negative of a renamed switch
            new = renamed[f"--{flag[5:]}"]
            head, _, last = new[2:].rpartition(".")
            flag = "--" + (f"{head}." if head else "") + "no-" + last
            say(f"note: --{token[2:]} is deprecated; write {flag}")
        tp, optional = _optional(flags.get(flag))
        head, _, last = flag[2:].rpartition(".")  # a nested switch's negative: --section.no-name
        positive = flags.get("--" + (f"{head}." if head else "") + last[3:]) if last.startswith("no-") else None
        if tp is bool and optional:  # an optional switch of old: given bare for True
            if not eq and (i >= len(argv) or argv[i] not in ("True", "False", "None")):
                say(f"note: a bare {flag} is deprecated; write {flag} True")
                out += [flag, "True"]
                continue
        if positive is not None and _optional(positive) == (bool, True):
            name = "--" + (f"{head}." if head else "") + last[3:]
            say(f"note: {flag} is deprecated; write {name} False")
            out += [name, "False"]
            continue
        if tp is None or tp is bool:
            out.append(flag if not eq else f"{flag}={inline}")
            continue
        if eq:
            value = inline
        elif i < len(argv):
            value = argv[i]
            i += 1
        else:
            out.append(flag)
            continue
        out.append(flag)
        if optional and value.strip().lower() == "none" and value != "None":
            say(f"note: {flag} {value} is deprecated; write {flag} None")
            out.append("None")
        elif typing.get_origin(tp) is tuple and ("," in value or value == ""):
            items = [x.strip() for x in value.split(",") if x.strip()]
            say(f"note: comma lists are deprecated; write {flag} {' '.join(items)}".rstrip())
            out += items
        elif eq and flag == token.partition("=")[0]:
            out[-1] = token  # nothing to rewrite: as given
        else:
            out.append(value)
    return out
