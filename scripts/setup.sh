#!/usr/bin/env bash
# Create .venv (once) and install wresdyn with its dependencies into it.
#
# PyTorch: on the project machines `pip install torch==2.13.0` takes a local CPU wheel; an unpinned
# torch would download a multi-GB CUDA build. To use a GPU, install your CUDA build of torch into the
# venv first (e.g. `.venv/bin/pip install torch --index-url https://download.pytorch.org/whl/cu128`)
# and set WRESDYN_TORCH=skip.
#
# `scripts/setup.sh usd` (also run by `dev`) makes .venv-usd: the MJCF/URDF -> USD converters of `wresdyn export`
# (wresdyn.export.convert runs them as a subprocess). They build on usd-exchange, whose wheel bundles its own OpenUSD
# and breaks next to usd-core, and mujoco-usd-converter 0.8.0 pins mujoco<3.17 while Newton 1.8 pins 3.17: it is
# installed without its pins, next to the MuJoCo that wresdyn runs (it converts under 3.17).
set -euo pipefail
cd "$(dirname "$0")/.."
extras=${1:-dev}

usd_venv() {
  local stamp=.venv-usd/.wresdyn-installed
  if [[ -f $stamp && $stamp -nt scripts/setup.sh ]]; then return 0; fi
  [[ -x .venv-usd/bin/python ]] || python3 -m venv .venv-usd
  .venv-usd/bin/python -m pip install -q --upgrade pip
  .venv-usd/bin/python -m pip install -q "usd-exchange==3.0.1" "mujoco>=3.17,<3.18" "newton-usd-schemas>=0.6" \
    "numpy-stl>=3.2" "tinyobjloader>=2.0.0rc13" "pycollada>=0.9.2"
  .venv-usd/bin/python -m pip install -q --no-deps "mujoco-usd-converter==0.8.0" "urdf-usd-converter==0.3.4"
  .venv-usd/bin/python -c "import mujoco_usd_converter, urdf_usd_converter"
  touch "$stamp"
}

if [[ $extras == usd ]]; then usd_venv; exit 0; fi
if [[ $extras == dev ]]; then usd_venv; fi
stamp=.venv/.wresdyn-installed-$extras
if [[ -f $stamp && $stamp -nt pyproject.toml ]]; then exit 0; fi
[[ -x .venv/bin/python ]] || python3 -m venv .venv
.venv/bin/python -m pip install -q --upgrade pip
if [[ ${WRESDYN_TORCH:-cpu} != skip ]]; then
  .venv/bin/python -m pip install -q "torch==${WRESDYN_TORCH_VERSION:-2.13.0}"
fi
.venv/bin/python -m pip install -q -e ".[$extras]"
touch "$stamp"
