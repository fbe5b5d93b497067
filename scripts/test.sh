#!/usr/bin/env bash
# Install (once) and run the test suite. Extra arguments go to pytest (e.g. --run-slow, -k parity).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh dev
exec .venv/bin/python -m pytest "$@"
