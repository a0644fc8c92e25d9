"""The network's high-side faces from a mirrored pass: ``agndc eval`` with the prediction replaced.

Training samples put every shape one empty voxel (plus the lattice padding) from the lattice's
low end, so the network knows where a low-side face lies in its layer better than a high-side
one, whose distance to the lattice's high end varies with the padding to a multiple of 4
(``inference.trained_window``; docs/experiments/frame-phase.md, flat-face-bias.md). This study
runs the network a second time on the lattice mirrored along all three axes, where the high
sides become low sides, and takes each cell's coordinate along an axis from the pass in which
the cell is nearer the low end of the shape's occupied box:

    .venv/bin/python research/mirror_border.py DATA -o OUT --res 64 [--shifts 3]

``--average`` takes the mean of the two passes instead (the two-flip mirror ensemble).
"""

from __future__ import annotations

import numpy as np
from stage_eval import eval_parser, run_eval


def mirrored_back(vertex_f: np.ndarray) -> np.ndarray:
    """(X, Y, Z, 3) cell offsets predicted on ``np.flip(lattice)`` -> the same cells' offsets in
    the original lattice. Cell c of the original spans points c and c + 1, which are points
    N - 1 - c and N - 2 - c of the mirror, i.e. the mirror's cell N - 2 - c; its offset o along
    an axis is 1 - o. The last layer of cells (no cell) stays as it was, unused."""
    back = np.flip(vertex_f, axis=(0, 1, 2)).copy()
    out = back.copy()
    out[:-1, :-1, :-1] = 1.0 - back[1:, 1:, 1:]
    return out


def nearer_high(lattice: np.ndarray) -> list[np.ndarray]:
    """Per axis a, an (N_a,) bool over cell indices: the cell is nearer the high end of the
    shape's occupied points than the low end."""
    occupied = np.argwhere(lattice)
    lo, hi = occupied.min(0), occupied.max(0)
    return [np.arange(n) + 0.5 - lo[a] > hi[a] - (np.arange(n) + 0.5)
            for a, n in enumerate(lattice.shape)]


def main() -> None:
    parser = eval_parser(__doc__)
    parser.add_argument("--average", action="store_true")
    args = parser.parse_args()

    from agndc_core import pipeline

    predict = pipeline._predict

    def both(method, lattice, *rest, **options):
        vertex = predict(method, lattice, *rest, **options)
        if not lattice.any():
            return vertex
        flipped = np.ascontiguousarray(np.flip(lattice, axis=(0, 1, 2)))
        back = mirrored_back(predict(method, flipped, *rest, **options))
        if args.average:
            return 0.5 * (vertex + back)
        out = vertex.copy()
        for axis, high in enumerate(nearer_high(lattice)):
            shape = [1, 1, 1]
            shape[axis] = -1
            mask = np.broadcast_to(high.reshape(shape), lattice.shape)
            out[..., axis][mask] = back[..., axis][mask]
        return out

    pipeline._predict = both
    run_eval(args)


if __name__ == "__main__":
    main()
