"""``python -m wresdyn.cli``: the ``wresdyn`` command."""

from wresdyn.cli import entry

entry()
