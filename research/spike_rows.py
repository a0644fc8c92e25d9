"""Rows of sharp cones on a slab (spires, crown points, the teeth of a printed gazebo roof):
whether the networks lose to marching cubes on spikes in general, as AGNDC does on the dev mesh
``1004825``, whose cones are thinner than a voxel over half their length.

    .venv/bin/python research/spike_rows.py -o runs/spikes -n 12
    .venv/bin/agndc eval runs/spikes -o out/spikes --res 64 --samples 30000 \
        --methods mc,undc,agndc,agndc_fast,oracle_binary

Each shape (deterministic in its seed, a stream of its own): a slab 3-8 voxels thick at 64³,
0.1-0.3 of its length wide, with 3-8 cones along it, each 10-28 voxels tall with a base radius
of 2-6 voxels (``--radius``; half-angles 4-30°), pointing up or down, off the row's line by up
to 0.3 voxel; every third shape turned by Euler angles along a random direction, 3-12° in all.
Written as OBJ files with a ``MANIFEST.csv`` (kind ``print``) that ``agndc eval`` reads.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

#: the seed stream of these shapes (apart from the training generator's and the families')
SEED_STREAM = 777
#: one voxel at 64³, in units of the longest side (the voxeliser spans it with 62)
VOXEL = 1.0 / 62


def spike_row(seed: int, radius=(2.0, 6.0)) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) vertices (bounding box centred, longest side 1), (F, 3) faces of one shape; the
    cones' base radii drawn from ``radius`` (voxels at 64³)."""
    from manifold3d import Manifold

    rng = np.random.default_rng((seed, SEED_STREAM))
    count = int(rng.integers(3, 9))
    thickness = rng.uniform(3, 8) * VOXEL
    width = rng.uniform(0.1, 0.3)
    shape = Manifold.cube((1.0, width, thickness), center=True)
    for x in np.linspace(-0.44, 0.44, count):
        height = rng.uniform(10, 28) * VOXEL
        base = min(rng.uniform(*radius) * VOXEL, width / 2)
        off = rng.uniform(-0.3, 0.3, size=2) * VOXEL
        cone = Manifold.cylinder(height, base, 0.0, 48).translate(
            (x + off[0], off[1], thickness / 2 - 0.001))
        if rng.random() < 0.5:
            cone = cone.mirror((0, 0, 1))  # pointing down from the slab's lower face
        shape = shape + cone
    return turned_arrays(shape, rng, seed)


def turned_arrays(shape, rng, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) vertices (bounding box centred, longest side 1), (F, 3) faces of a manifold;
    every third seed's turned first by Euler angles along a random direction, 3-12° in all."""
    from agndc_core.study.shapes import _to_arrays

    if seed % 3 == 2:
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        shape = shape.rotate(tuple(axis * rng.uniform(3, 12)))
    return _to_arrays(shape)  # centred, longest side 1


def write_set(out: Path, count: int, prefix: str, kind: str, shape: str, build) -> None:
    """``count`` meshes ``build(seed)`` as ``out/PREFIX_SEED.obj`` with a ``MANIFEST.csv`` of
    class ``kind`` that ``agndc eval`` reads."""
    from agndc_core.study.validation import save_shape, write_manifest

    out.mkdir(parents=True, exist_ok=True)
    rows = [save_shape(out, f"{prefix}_{seed}.obj", kind, shape, seed, *build(seed))
            for seed in range(count)]
    write_manifest(out, rows)
    print(f"{len(rows)} shapes in {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", type=Path, required=True)
    parser.add_argument("-n", type=int, default=12)
    parser.add_argument("--radius", default="2,6", help="LO,HI base radius, voxels at 64³")
    args = parser.parse_args()

    radius = tuple(float(r) for r in args.radius.split(","))
    write_set(args.out, args.n, "spikes", "print", "spike_row",
              lambda seed: spike_row(seed, radius))


if __name__ == "__main__":
    main()
