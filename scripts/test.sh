#!/usr/bin/env bash
# Install (once) and run the test suite. Extra arguments go to pytest (e.g. --run-slow, -k parity).
# The tests run in WRESDYN_TEST_WORKERS processes (pytest-xdist; default 2, the CI machine's cores): each test is
# one process's work, so a second process halves the wall-clock; an idle process takes tests queued for the other
# (--dist worksteal), so the minute-long tests do not end up at one process's end. WRESDYN_TEST_WORKERS=0 runs them
# in this process.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh dev
exec .venv/bin/python -m pytest -n "${WRESDYN_TEST_WORKERS:-2}" --dist worksteal "$@"
