#!/usr/bin/env bash
# Create .venv-bpy: Blender as a Python module (bpy 4.5 LTS from PyPI) + agndc_core (editable,
# without torch: the extension runs its networks in numpy, as a user's Blender has no torch) +
# pytest, for tests/blender, build_addon.py and scripts/agndc_batch.py without a Blender
# executable. Idempotent: later runs only install what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3.11}"   # bpy 4.5 wheels exist for CPython 3.11 only
command -v "$PYTHON" >/dev/null || PYTHON=python3
VENV=.venv-bpy
if [ ! -x "$VENV/bin/python" ]; then
    "$PYTHON" -m venv "$VENV"
fi
# numpy < 2: bpy 4.5 pins it.
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
    'bpy==4.5.*' 'numpy>=1.26,<2' 'pytest>=8'
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check -e .
# an environment made before the extension dropped torch: take it out, the tests prove it unneeded
"$VENV/bin/python" -m pip uninstall --quiet --yes torch 2>/dev/null || true
"$VENV/bin/python" -m pip check --disable-pip-version-check >/dev/null
# os._exit: bpy 4.5 can hang at interpreter exit (docs/blender.md)
"$VENV/bin/python" -c "
import importlib.util, os, sys, bpy, numpy, agndc_core
assert importlib.util.find_spec('torch') is None, 'torch must not be in the Blender test env'
print(f'bpy env ready: bpy {bpy.app.version_string}, numpy {numpy.__version__}, no torch')
sys.stdout.flush(); os._exit(0)"
