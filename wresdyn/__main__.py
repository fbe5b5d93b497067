"""``python -m wresdyn``: the ``wresdyn`` command line (:mod:`wresdyn.cli`)."""

from wresdyn.cli import entry

entry()
