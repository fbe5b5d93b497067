#!/usr/bin/env bash
# Create .venv (once) and install wresdyn with its dependencies into it.
#
# PyTorch: on the project machines `pip install torch==2.13.0` takes a local CPU wheel; an unpinned
# torch would download a multi-GB CUDA build. To use a GPU, install your CUDA build of torch into the
# venv first (e.g. `.venv/bin/pip install torch --index-url https://download.pytorch.org/whl/cu128`)
# and set WRESDYN_TORCH=skip.
set -euo pipefail
cd "$(dirname "$0")/.."
extras=${1:-dev}
stamp=.venv/.wresdyn-installed-$extras
if [[ -f $stamp && $stamp -nt pyproject.toml ]]; then exit 0; fi
[[ -x .venv/bin/python ]] || python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
if [[ ${WRESDYN_TORCH:-cpu} != skip ]]; then
  .venv/bin/python -m pip install -q "torch==${WRESDYN_TORCH_VERSION:-2.13.0}"
fi
.venv/bin/python -m pip install -q -e ".[$extras]"
touch "$stamp"
