"""``python -m wresdyn.cli``: the ``wresdyn`` command."""

import sys

from wresdyn.cli import main

sys.exit(main())
