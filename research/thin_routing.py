"""Thin parts to the distilled network: ``agndc eval`` with AGNDC's vertices replaced by
``agndc_fast``'s in the cells of thin parts of the shape.

On the generated thin sheets the shipped AGNDC closes 42 % of the MC→oracle_binary headroom
and ``agndc_fast`` (the same cascade without snake convolutions or attention, distilled from an
earlier AGNDC) 80 %; on the validation family and the dev meshes the two are within 1 %. A
cell is *thin* when no lattice point within ``--radius`` points of its corners lies deeper
inside the shape than ``--depth`` voxels (Euclidean distance to the nearest outside point): a
plate k voxels thick has points at most ceil(k / 2) deep, the faces of a thick solid have deeper
points a few voxels in.

    .venv/bin/python research/thin_routing.py DATA -o OUT --res 64 [--shifts 3] \
        --depth 1 --radius 3
"""

from __future__ import annotations

import numpy as np
from stage_eval import eval_parser, run_eval_with_network


def thin_cells(lattice: np.ndarray, depth: float, radius: int) -> np.ndarray:
    """(X, Y, Z) bool over the lattice's cells (cell c spans points c .. c + 1; the last layer
    of each axis is not a cell and is False): no point within ``radius`` points (a cube) of the
    cell's corners is more than ``depth`` voxels from the nearest outside point."""
    from scipy import ndimage

    inside = np.asarray(lattice, dtype=bool)
    deep = ndimage.distance_transform_edt(inside)  # 0 outside, >= 1 inside
    # a cube of 2 * radius + 2 points from the cell's low corner - radius: every point within
    # radius of any of its 8 corners
    near = ndimage.maximum_filter(deep, size=2 * radius + 2, origin=-1, mode="constant")
    thin = (near >= 1) & (near <= depth)  # some inside point near: the shape, not empty space
    thin[-1, :, :] = thin[:, -1, :] = thin[:, :, -1] = False
    return thin


def main() -> None:
    parser = eval_parser(__doc__, methods=False)
    parser.add_argument("--depth", type=float, default=1.0, help="voxels: the deepest inside "
                        "point a thin part has (1: two layers thick, 2: four)")
    parser.add_argument("--radius", type=int, default=3, help="points around a cell searched "
                        "for a deeper point")
    args = parser.parse_args()

    def routed(lattice, vertex, fast):
        thin = thin_cells(lattice, args.depth, args.radius)
        if not thin.any():
            return vertex
        vertex = vertex.copy()
        vertex[thin] = fast()[thin]
        return vertex

    run_eval_with_network(args, "agndc_fast", routed)


if __name__ == "__main__":
    main()
