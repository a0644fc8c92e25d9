#!/usr/bin/env bash
# Create .venv-bpy: Blender as a Python module (bpy 4.5 LTS from PyPI) + torch + agndc_core
# (editable) + pytest, for tests/blender, build_addon.py and scripts/agndc_batch.py without a
# Blender executable. Idempotent: later runs only install what is missing.
set -euo pipefail
cd "$(dirname "$0")/.."
PYTHON="${PYTHON:-python3.11}"   # bpy 4.5 wheels exist for CPython 3.11 only
command -v "$PYTHON" >/dev/null || PYTHON=python3
VENV=.venv-bpy
if [ ! -x "$VENV/bin/python" ]; then
    "$PYTHON" -m venv "$VENV"
fi
# numpy < 2: bpy 4.5 pins it. torch 2.13.0: the CPU wheel where one is on disk (pip find-links).
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check \
    'bpy==4.5.*' 'torch==2.13.0' 'numpy>=1.26,<2' 'pytest>=8'
"$VENV/bin/python" -m pip install --quiet --disable-pip-version-check -e .
"$VENV/bin/python" -m pip check --disable-pip-version-check >/dev/null
# os._exit: bpy 4.5 can hang at interpreter exit (docs/blender.md)
"$VENV/bin/python" -c "
import os, sys, bpy, torch, numpy, agndc_core
print(f'bpy env ready: bpy {bpy.app.version_string}, torch {torch.__version__}, numpy {numpy.__version__}')
sys.stdout.flush(); os._exit(0)"
