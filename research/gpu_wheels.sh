#!/usr/bin/env bash
# Run HERE (not on the GPU machine): download the Python 3.12 wheels the GPU machine lacks into
# .whl/ (git-ignored through .git/info/exclude), to send with each GPU command. The GPU machine
# already has torch, numpy, scipy, scikit-image, safetensors and tqdm; data generation needs
# manifold3d (the shape booleans), trimesh and rtree (labels: nearest points on the mesh). See docs/training.md.
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p "$(git rev-parse --git-dir)/info"
exclude="$(git rev-parse --git-dir)/info/exclude"
grep -qx "/.whl/" "$exclude" 2>/dev/null || echo "/.whl/" >> "$exclude"
mkdir -p .whl
for pkg in manifold3d==3.5.4 trimesh==5.2.0 rtree==1.4.1; do
    python3 -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
        --implementation cp --platform manylinux_2_28_x86_64 --platform manylinux_2_27_x86_64 \
        --platform manylinux_2_17_x86_64 --platform manylinux2014_x86_64 \
        --platform any -d .whl "$pkg"
done
ls -l .whl
