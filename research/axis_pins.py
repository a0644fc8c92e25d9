"""Plates with pins, bosses and holes along an axis: the thin round parts that the flat-patch
stages facet (docs/experiments/flat-patches.md, "Known loss: thin round parts along an axis").

    .venv/bin/python research/axis_pins.py -o runs/pins -n 24
    .venv/bin/agndc eval runs/pins -o out/pins --res 64 --samples 30000 \
        --methods mc,undc,agndc,oracle_binary

Each shape (deterministic in its seed, a stream of its own): a plate 3-8 voxels thick at 64³,
0.3-0.6 of its length wide, with 2-6 pins standing on it (radius 2-8 voxels, 6-30 voxels tall,
half of them on its lower face), 0-3 round holes through it (radius 2-6 voxels) and, on every
other shape, a shaft lying along the plate (radius 2-6 voxels); every axis is a grid axis, and
every centre lies off the voxel lattice by a random fraction of a voxel. Written as OBJ files with
a ``MANIFEST.csv`` (kind ``cad``) that ``agndc eval`` reads.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from spike_rows import VOXEL, write_set

#: the seed stream of these shapes (apart from the training generator's and the families')
SEED_STREAM = 888
#: segments of a cylinder's round side: faceting far finer than a voxel at 64³
SEGMENTS = 96


def pin_plate(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) vertices (bounding box centred, longest side 1), (F, 3) faces of one shape."""
    from manifold3d import Manifold

    from agndc_core.study.shapes import _to_arrays

    rng = np.random.default_rng((seed, SEED_STREAM))
    thickness = rng.uniform(3, 8) * VOXEL
    width = rng.uniform(0.3, 0.6)
    shape = Manifold.cube((1.0, width, thickness), center=True)
    for _ in range(int(rng.integers(0, 4))):
        radius = rng.uniform(2, 6) * VOXEL
        x, y = rng.uniform(-0.4, 0.4), rng.uniform(-0.35, 0.35) * width
        hole = Manifold.cylinder(2 * thickness, radius, radius, SEGMENTS, center=True)
        shape = shape - hole.translate((x, y, 0.0))
    for _ in range(int(rng.integers(2, 7))):
        radius = rng.uniform(2, 8) * VOXEL
        height = rng.uniform(6, 30) * VOXEL
        x = rng.uniform(-0.45, 0.45)
        y = rng.uniform(-0.4, 0.4) * width
        pin = Manifold.cylinder(height, radius, radius, SEGMENTS).translate(
            (x, y, thickness / 2 - 0.001))
        if rng.random() < 0.5:
            pin = pin.mirror((0, 0, 1))  # standing on the lower face
        shape = shape + pin
    if seed % 2 == 1:
        radius = rng.uniform(2, 6) * VOXEL
        y = rng.uniform(-0.3, 0.3) * width
        length = rng.uniform(0.4, 0.9)
        shaft = Manifold.cylinder(length, radius, radius, SEGMENTS, center=True)
        shaft = shaft.rotate((0.0, 90.0, 0.0)).translate(
            (0.0, y, thickness / 2 + radius - 0.5 * VOXEL))
        shape = shape + shaft
    return _to_arrays(shape)  # centred, longest side 1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", type=Path, required=True)
    parser.add_argument("-n", type=int, default=24)
    args = parser.parse_args()
    write_set(args.out, args.n, "pins", "cad", "axis_pins", pin_plate)


if __name__ == "__main__":
    main()
