"""Sphinx extension of the wresdyn docs.

- ``{wresdyn-cli}`` directive: the CLI reference, one section per subcommand with its ``--help``, built from
  the parser of :mod:`wresdyn.cli` at build time, so the page cannot drift from the code.
- ``{repo}`` role: a link to a file or folder of the repository (raw benchmark output, scripts) that warns,
  and so fails the strict build, when the path does not exist.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from docutils import nodes
from sphinx.util.docutils import SphinxDirective

ROOT = Path(__file__).resolve().parents[2]
HELP_COLUMNS = "100"  # a fixed width: argparse wraps to the terminal, and the page must not depend on it


def cli_parsers() -> tuple[argparse.ArgumentParser, dict[str, argparse.ArgumentParser]]:
    """The ``wresdyn`` parser and its subcommands' parsers, registered as :func:`wresdyn.cli.main` does."""
    from wresdyn.cli import build_parser

    return build_parser()


def _help(parser: argparse.ArgumentParser) -> str:
    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_COLUMNS
    try:
        return parser.format_help()
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old


class CliDirective(SphinxDirective):
    """``wresdyn --help``, then a section per subcommand with its one-line summary and ``--help``."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        parser, subs = cli_parsers()
        out: list[nodes.Node] = [nodes.literal_block(text=_help(parser), language="text")]
        for name, p in subs.items():
            sec = nodes.section(ids=[f"wresdyn-{name}"], names=[f"wresdyn {name}"])
            sec += nodes.title(text=f"wresdyn {name}")
            sec += nodes.paragraph(text=p.description[0].upper() + p.description[1:] + ".")
            sec += nodes.literal_block(text=_help(p), language="text")
            self.env.note_dependency(str(ROOT / "wresdyn" / "cli" / f"{name}.py"))
            out.append(sec)
        return out


def repo_role(name, rawtext, text, lineno, inliner, options=None, content=None):
    """``{repo}`path``: a link to ``path`` in the repository, shown as code; a missing path is a warning."""
    path = text.strip()
    env = inliner.document.settings.env
    if not (ROOT / path).exists():
        msg = inliner.reporter.warning(f"{{repo}}: no such file or folder in the repository: {path}", line=lineno)
        return [nodes.literal(rawtext, path)], [msg]
    base = env.config.wresdyn_source_url
    if base:
        url = f"{base.rstrip('/')}/{path}"
    else:  # relative to where the page's HTML lands in the output folder
        page_dir = Path(env.app.outdir) / Path(env.docname).parent
        url = os.path.relpath(ROOT / path, page_dir).replace(os.sep, "/")
        if (ROOT / path).is_dir() and not url.endswith("/"):
            url += "/"
    ref = nodes.reference(rawtext, "", refuri=url)
    ref += nodes.literal(path, path)
    return [ref], []


def escape_pipes(app, what, name, obj, options, lines: list[str]) -> None:
    """Docstrings write norms as ``|x|`` (plain text in the terminal); reST reads ``|x|`` as a substitution.
    Escape the bars outside inline literals and tables, before napoleon parses the sections."""
    in_literal = False
    for i, line in enumerate(lines):
        text = line.strip()
        grid_row = text.startswith(("+-", "+=", "| ")) or (text.startswith("|") and text.endswith("|"))
        if grid_row:
            continue
        parts = line.split("``")
        for j, part in enumerate(parts):
            literal = in_literal if j % 2 == 0 else not in_literal
            if not literal:
                parts[j] = part.replace("|", r"\|")
        in_literal ^= (len(parts) - 1) % 2 == 1
        lines[i] = "``".join(parts)


def setup(app):
    app.add_config_value("wresdyn_source_url", "", "html")
    app.add_directive("wresdyn-cli", CliDirective)
    app.add_role("repo", repo_role)
    app.connect("autodoc-process-docstring", escape_pipes, priority=400)  # napoleon runs at 500
    return {"version": "1", "parallel_read_safe": True, "parallel_write_safe": True}
