#!/usr/bin/env bash
# Install (once) and run the main job on the embedded defaults. Extra arguments go to `wresdyn demo`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh dev
exec .venv/bin/wresdyn demo "$@"
