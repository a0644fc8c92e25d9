"""Where AGNDC puts the faces of an axis-aligned box on randomly shifted grids, with and without
the high-border margin.

A 1 x 0.8 x 0.5 box is voxelised at RES on the centred grid and on K-1 grids shifted by seeded
uniform sub-voxel offsets; AGNDC (grid alone) remeshes each with ``methods.Method.high_margin``
set to every value of ``--margins``. Per face (x-, x+, y-, y+, z-, z+) the mean signed offset of
the output vertices on it (outward positive, voxels; vertices within 2 voxels of the other
faces left out), and the RMS of those means over the shifted grids: on a shifted grid the
depth of an axis-aligned face inside its layer is what binary input cannot tell, so a guess at
the layer's midpoint scores 1/sqrt(12) = 0.289 voxel there.

    .venv/bin/python research/shifted_face_offsets.py --grids 25 --margins 0 4

docs/experiments/high-border-margin.md has the measurement.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np
import trimesh

from agndc_core import methods
from agndc_core.pipeline import remesh_mesh

EXTENTS = np.array([1.0, 0.8, 0.5])
FACES = ("x-", "x+", "y-", "y+", "z-", "z+")


def face_offsets(vertices: np.ndarray, voxel: float) -> np.ndarray:
    """(6,) mean signed outward offset (voxels) of the vertices on each face of the box."""
    half = EXTENTS / 2
    means = []
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        inner = np.all(np.abs(vertices[:, others]) < half[others] - 2 * voxel, axis=1)
        for sign in (-1, 1):
            outward = (sign * vertices[:, axis] - half[axis]) / voxel
            chosen = inner & (np.abs(outward) < 1.0)
            means.append(outward[chosen].mean())
    return np.array(means)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--grids", type=int, default=25, help="the centred grid and K-1 shifted")
    parser.add_argument("--margins", type=int, nargs="+", default=[0, 4])
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--seed", type=int, default=7)
    args = parser.parse_args()

    box = trimesh.creation.box(EXTENTS)
    rng = np.random.default_rng(args.seed)
    shifts = [np.zeros(3)] + list(rng.uniform(-0.5, 0.5, (args.grids - 1, 3)))
    shipped = methods.BY_NAME["agndc"]
    for margin in args.margins:
        methods.BY_NAME["agndc"] = replace(shipped, high_margin=margin)
        found = []
        for shift in shifts:
            result = remesh_mesh(box.vertices, box.faces, resolution=args.res, method="agndc",
                                 source_bounds=False, shift=shift)
            found.append(face_offsets(result.vertices, abs(result.grid.affine[0, 0])))
        found = np.array(found)
        shifted = found[1:]
        rms = np.sqrt((shifted ** 2).mean(axis=0))
        print(f"margin {margin}: centred grid " + ", ".join(
            f"{f} {o:+.3f}" for f, o in zip(FACES, found[0])))
        print(f"  RMS over {len(shifted)} shifted grids " + ", ".join(
            f"{f} {o:.3f}" for f, o in zip(FACES, rms)))
        print(f"  low faces {np.sqrt((shifted[:, 0::2] ** 2).mean()):.3f}, "
              f"high faces {np.sqrt((shifted[:, 1::2] ** 2).mean()):.3f}")
    methods.BY_NAME["agndc"] = shipped


if __name__ == "__main__":
    main()
