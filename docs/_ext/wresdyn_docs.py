"""Sphinx extension of the wresdyn docs.

- ``{wresdyn-cli}`` directive: the CLI reference, one section per subcommand with its ``--help``, built from
  the command line of :mod:`wresdyn.cli` (each command's dataclass, read by tyro) at build time, so the page cannot
  drift from the code.
- ``{repo}`` role: a link to a file or folder of the repository (raw benchmark output, scripts) that warns,
  and so fails the strict build, when the path does not exist.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import os
from pathlib import Path

from docutils import nodes
from sphinx.util.docutils import SphinxDirective

ROOT = Path(__file__).resolve().parents[2]
HELP_COLUMNS = "100"  # a fixed width: tyro wraps to the terminal, and the page must not depend on it


def command_help(argv: list[str]) -> str:
    """What ``wresdyn ARGV`` prints (``--help``), at :data:`HELP_COLUMNS` columns."""
    from wresdyn.cli import parse_command

    old = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_COLUMNS
    out = io.StringIO()
    try:
        with contextlib.redirect_stdout(out):
            parse_command(argv)
    except SystemExit:
        pass
    finally:
        if old is None:
            del os.environ["COLUMNS"]
        else:
            os.environ["COLUMNS"] = old
    return out.getvalue()


class CliDirective(SphinxDirective):
    """``wresdyn --help``, then a section per subcommand with its one-line summary and ``--help``."""

    has_content = False

    def run(self) -> list[nodes.Node]:
        from wresdyn.cli import COMMANDS, top_help

        out: list[nodes.Node] = [nodes.literal_block(text=top_help(), language="text")]
        for name, (module, summary) in COMMANDS.items():
            sec = nodes.section(ids=[f"wresdyn-{name}"], names=[f"wresdyn {name}"])
            sec += nodes.title(text=f"wresdyn {name}")
            sec += nodes.paragraph(text=summary[0].upper() + summary[1:] + ".")
            sec += nodes.literal_block(text=command_help([name, "--help"]), language="text")
            for flag in getattr(importlib.import_module(module), "VARIANT_FLAGS", ()):  # deploy --floor's own flags
                sec += nodes.paragraph(text=f"With {flag}:")
                sec += nodes.literal_block(text=command_help([name, flag, "--help"]), language="text")
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
