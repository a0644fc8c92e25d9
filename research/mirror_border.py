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
from stage_eval import eval_parser, run_eval


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


def nearer_high(lattice: np.ndarray) -> list[np.ndarray]:
    """Per axis a, an (N_a,) bool over cell indices: the cell is nearer the high end of the
    shape's occupied points than the low end."""
    occupied = np.argwhere(lattice)
    lo, hi = occupied.min(0), occupied.max(0)
    return [np.arange(n) + 0.5 - lo[a] > hi[a] - (np.arange(n) + 0.5)
            for a, n in enumerate(lattice.shape)]


def facing_high(lattice: np.ndarray) -> list[np.ndarray]:
    """Per axis a, an (X, Y, Z) bool over cells (the last layer of each axis False): more of the
    cell's corners are inside on its low side along a than on its high side, i.e. the surface
    through the cell faces the high end of axis a."""
    inside = lattice.astype(np.int8)
    # (X-1, Y-1, Z-1) corner counts of each cell's low and high halves along each axis
    sums = []
    for axis in range(3):
        halves = []
        for side in (0, 1):
            total = np.zeros(tuple(n - 1 for n in lattice.shape), dtype=np.int8)
            for i in (0, 1):
                for j in (0, 1):
                    index = [None, None, None]
                    others = [b for b in range(3) if b != axis]
                    index[axis] = side
                    index[others[0]], index[others[1]] = i, j
                    total += inside[tuple(slice(o, o + n - 1)
                                          for o, n in zip(index, lattice.shape))]
            halves.append(total)
        high = np.zeros(lattice.shape, dtype=bool)
        high[:-1, :-1, :-1] = halves[0] > halves[1]
        sums.append(high)
    return sums


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

    from agndc_core import pipeline

    predict = pipeline._predict

    def both(method, lattice, *rest, **options):
        vertex = predict(method, lattice, *rest, **options)
        if not lattice.any():
            return vertex
        axes = (0, 1, 2)
        if args.thin:  # only the axes along which the occupied points are <= args.thin apart
            occupied = np.argwhere(lattice)
            span = occupied.max(0) - occupied.min(0)
            axes = tuple(int(a) for a in np.flatnonzero(span <= args.thin))
            if not axes:
                return vertex
        flipped = np.ascontiguousarray(np.flip(lattice, axis=axes))
        back = mirrored_back(predict(method, flipped, *rest, **options), axes)
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

    pipeline._predict = both
    run_eval(args)


if __name__ == "__main__":
    main()
