"""``python -m wresdyn``: the ``wresdyn`` command line (:mod:`wresdyn.cli`)."""

import sys

from wresdyn.cli import main

sys.exit(main())
