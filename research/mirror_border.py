"""The network's high-side faces from a mirrored pass: ``agndc eval`` with the prediction replaced.

Training samples put every shape one empty voxel (plus the lattice padding) from the lattice's
low end, so the network knows where a low-side face lies in its layer better than a high-side
one, whose distance to the lattice's high end varies with the padding to a multiple of 4
(``inference.trained_window``; docs/experiments/frame-phase.md, flat-face-bias.md). This study
runs the network a second time on the lattice mirrored along all three axes, where the high
sides become low sides, and takes each cell's coordinate along an axis from the pass in which
the cell is nearer the low end of the shape's occupied box:

    .venv/bin/python research/mirror_border.py DATA -o OUT --res 64 [--shifts 3]

``--average`` takes the mean of the two passes instead (the two-flip mirror ensemble),
``--by-facing`` the mirrored pass's coordinate where the cell's surface faces the high end,
``--thin N`` mirrors only the axes along which the shape is thin.
"""

from __future__ import annotations

import numpy as np
from stage_eval import eval_parser, run_eval_with_prediction


def mirrored_back(vertex_f: np.ndarray, axes=(0, 1, 2)) -> np.ndarray:
    """(X, Y, Z, 3) cell offsets predicted on ``np.flip(lattice, axes)`` -> the same cells'
    offsets in the original lattice. Along a mirrored axis, cell c of the original spans points
    c and c + 1, which are points N - 1 - c and N - 2 - c of the mirror, i.e. the mirror's cell
    N - 2 - c; its offset o along that axis is 1 - o. The last layer of cells along a mirrored
    axis (no cell) holds nothing meaningful and is never used."""
    out = np.flip(vertex_f, axis=tuple(axes)).copy()
    for axis in axes:
        out = np.roll(out, -1, axis=axis)  # index c now holds the mirror's cell N - 2 - c
        out[..., axis] = 1.0 - out[..., axis]
    return out


def occupied_range(lattice: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3,) int lowest and highest occupied point index along each axis (a non-empty lattice),
    from ``flatpatches.outer_cell_layers``."""
    from agndc_core.flatpatches import outer_cell_layers

    outer = [outer_cell_layers(lattice, axis) for axis in range(3)]
    return (np.array([o[False] + 1 for o in outer]), np.array([o[True] for o in outer]))


def nearer_high(lattice: np.ndarray) -> list[np.ndarray]:
    """Per axis a, an (N_a,) bool over cell indices: the cell is nearer the high end of the
    shape's occupied points than the low end."""
    lo, hi = occupied_range(lattice)
    return [np.arange(n) + 0.5 - lo[a] > hi[a] - (np.arange(n) + 0.5)
            for a, n in enumerate(lattice.shape)]


def facing_high(lattice: np.ndarray) -> list[np.ndarray]:
    """Per axis a, an (X, Y, Z) bool over cells (the last layer of each axis False): more of the
    cell's 4 corners on its low side along a are inside than of the 4 on its high side, i.e. the
    surface through the cell faces the high end of axis a."""
    masks = []
    for axis in range(3):
        points = np.moveaxis(lattice.astype(np.int8), axis, -1)  # the axis last
        # inside corners of each 2 x 2 square of points across the axis, per layer
        square = points[:-1, :-1] + points[1:, :-1] + points[:-1, 1:] + points[1:, 1:]
        high = np.zeros(points.shape, dtype=bool)
        high[:-1, :-1, :-1] = square[..., :-1] > square[..., 1:]
        masks.append(np.moveaxis(high, -1, axis))
    return masks


def main() -> None:
    parser = eval_parser(__doc__)
    parser.add_argument("--average", action="store_true")
    parser.add_argument("--thin", type=int, default=0, help="mirror only the axes along which "
                        "the shape's occupied points lie at most this many layers apart (no "
                        "second pass when there is none)")
    parser.add_argument("--by-facing", action="store_true", help="take a cell's coordinate along "
                        "an axis from the mirrored pass where its surface faces that axis's "
                        "high end, instead of where the cell is nearer the high end")
    args = parser.parse_args()

    def both(method, lattice, predict):
        vertex = predict(method, lattice)
        if not lattice.any():
            return vertex
        axes = (0, 1, 2)
        if args.thin:  # only the axes along which the occupied points are <= args.thin apart
            lo, hi = occupied_range(lattice)
            axes = tuple(int(a) for a in np.flatnonzero(hi - lo <= args.thin))
            if not axes:
                return vertex
        flipped = np.ascontiguousarray(np.flip(lattice, axis=axes))
        back = mirrored_back(predict(method, flipped), axes)
        if args.average:
            return 0.5 * (vertex + back)
        out = vertex.copy()
        if args.by_facing:
            for axis, high in enumerate(facing_high(lattice)):
                if axis in axes:
                    out[..., axis][high] = back[..., axis][high]
            return out
        for axis, high in enumerate(nearer_high(lattice)):
            if axis not in axes:
                continue
            shape = [1, 1, 1]
            shape[axis] = -1
            mask = np.broadcast_to(high.reshape(shape), lattice.shape)
            out[..., axis][mask] = back[..., axis][mask]
        return out

    run_eval_with_prediction(args, both)


if __name__ == "__main__":
    main()
