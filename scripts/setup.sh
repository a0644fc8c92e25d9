#!/usr/bin/env bash
# Create .venv with the pinned dependencies and install agndc_core (editable). Idempotent.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3.11}"
command -v "$PYTHON" >/dev/null || PYTHON=python3
if [ ! -x .venv/bin/python ]; then
    "$PYTHON" -m venv .venv
fi
# torch==2.13.0 is pinned in pyproject.toml (the CPU wheel); numpy < 2 to match Blender's bpy
.venv/bin/python -m pip install --quiet --disable-pip-version-check -e '.[test,report,dask]'
.venv/bin/python -c "import agndc_core, torch; print('agndc_core ready, torch', torch.__version__)"
