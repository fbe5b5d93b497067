"""Sphinx configuration of the wresdyn documentation (MyST Markdown, pydata theme).

Build it strictly, as the test suite does (``tests/integration/test_docs.py``)::

    .venv/bin/sphinx-build -W --keep-going -b html docs docs/_build/html
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
# the package from this checkout (not an installed copy), and the docs' own extension
sys.path[:0] = [str(ROOT), str(DOCS / "_ext")]

import wresdyn  # noqa: E402

project = "wresdyn"
author = "wresdyn developers"
copyright = "wresdyn developers, Apache-2.0"
release = version = wresdyn.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "wresdyn_docs",  # the CLI reference from the parser, links to repository files that must exist
]
source_suffix = {".md": "markdown"}
exclude_patterns = ["_build", "_ext", "Thumbs.db", ".DS_Store"]

myst_enable_extensions = ["colon_fence", "dollarmath", "deflist"]
# `[text](page.md#a-heading)` is checked by the strict build for headings down to level 3
myst_heading_anchors = 3

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"members": True, "show-inheritance": False}
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_use_ivar = True

# Links to files of the repository ({repo}`path`): relative to the built page by default, so a local build
# opens the raw output next to it; set WRESDYN_SOURCE_URL (e.g. a forge's ".../blob/main") to link there.
wresdyn_source_url = os.environ.get("WRESDYN_SOURCE_URL", "")

html_theme = "pydata_sphinx_theme"
html_title = f"wresdyn {release}"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": [],
}
html_sidebars = {"**": ["sidebar-nav-bs"]}
html_static_path: list[str] = []

# "Returns:" blocks often describe a dict as one inline literal over several lines; napoleon's returns parser
# splits that at the first colon, so the section is rendered as written, under a rubric.
napoleon_custom_sections = ["Returns"]
