#!/usr/bin/env bash
# Create .venv with the pinned dependencies and install agndc_core (editable). Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3.11}"
command -v "$PYTHON" >/dev/null || PYTHON=python3
if [ ! -x .venv/bin/python ]; then
    "$PYTHON" -m venv .venv
fi
# the library needs no torch; this development environment adds it (training, the reference
# runtime) pinned to the CPU wheel, so pip never pulls a multi-GB CUDA build; numpy < 2 (bpy)
.venv/bin/python -m pip install --quiet --disable-pip-version-check \
    -e '.[train,test,report,dask]' 'torch==2.13.0'
.venv/bin/python -c "import agndc_core, torch; print('agndc_core ready, torch', torch.__version__)"
