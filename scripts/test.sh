#!/usr/bin/env bash
# Set up both environments and run the whole test suite: the core (plain pytest, no GPU, no
# network) and the Blender add-on tests (bpy 4.5 from PyPI in its own venv).
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
.venv/bin/ruff check .                       # lint rules and banned imports: pyproject.toml
# the core suite with a coverage floor (measured: 94 % of agndc_core's statements)
.venv/bin/python -m pytest -q tests/core --cov=agndc_core --cov-report=term:skip-covered \
    --cov-fail-under=90 "$@"
bash scripts/setup_bpy_env.sh
BLENDER_USER_RESOURCES="$(mktemp -d)" TMPDIR="$(mktemp -d)" \
    .venv-bpy/bin/python -m pytest -q -p no:cacheprovider tests/blender
