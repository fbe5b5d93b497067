"""The documentation builds strictly (every warning an error) and says what the code does.

The site under docs/ is built with ``sphinx-build -W --keep-going``: a broken cross reference, a heading anchor
that does not exist, a docstring reST cannot parse or a ``{repo}`` link to a file that is not in the repository
fails the suite. The CLI page is generated from the commands' dataclasses, so every flag of every command must be on it.
Sphinx, MyST and the theme come with the ``dev`` extra; without them this fails rather than skips, so CI cannot
pass with the docs unbuilt.
"""

from __future__ import annotations

import html
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("html")
    res = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html", "docs", str(out)],
                         cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert res.returncode == 0, res.stderr[-4000:]
    return out


def test_docs_build_strictly_and_cli_page_lists_every_flag(site):
    from wresdyn.cli import COMMANDS, command_flags

    page = html.unescape((site / "cli.html").read_text())
    for name in COMMANDS:
        assert f'id="wresdyn-{name}"' in page, name
        for flag in command_flags(name):
            assert flag in page, f"wresdyn {name} {flag}"


def test_readme_example_is_the_quickstart_and_runs(monkeypatch, capsys):
    """The README's Python example is examples/quickstart.py, and it prints the PD-only validation gap the
    results pages state (0.0807 rad). Run as ``python examples/quickstart.py`` runs it, in this process (where the
    modules it needs are loaded already)."""
    import runpy

    code = (ROOT / "examples" / "quickstart.py").read_text().strip()
    assert code in (ROOT / "README.md").read_text()
    monkeypatch.chdir(ROOT)
    runpy.run_path(str(ROOT / "examples" / "quickstart.py"), run_name="__main__")
    assert "PD-only mean |dq| on validation: 0.0807 rad" in capsys.readouterr().out
