"""`wresdyn fit` as the `wresdyn` executable runs it, with `--eval`'s helper processes forced on (HELPER=1: one,
HELPER=3: three) or off (HELPER=0) whatever the host's cores, where the tree has them (`wresdyn.cli.fit.HELPER_CORES`,
`HELPERS_CORES`); unset: the tree's rule."""
import os
import sys

import wresdyn.cli.fit as fit

if "HELPER" in os.environ and hasattr(fit, "HELPER_CORES"):
    fit.HELPER_CORES = 1 if os.environ["HELPER"] in ("1", "3") else 10**6
    if hasattr(fit, "HELPERS_CORES"):
        fit.HELPERS_CORES = 1 if os.environ["HELPER"] == "3" else 10**6
from wresdyn.cli import entry

sys.argv[0] = "wresdyn"
entry()
