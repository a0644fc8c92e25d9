"""More empty space past the shape's high end: ``agndc eval`` with the network run on the
lattice padded by ``--extra`` empty points after its last point along every axis (so its
multiple-of-4 size is kept with 4, 8, ...), the prediction cropped back.

Training samples are voxelised meshes framed by ``pad_to_lattice``: one empty voxel and one
lattice layer before the shape, one empty voxel and 0-3 layers after it. On a plate 2.5 voxels
thick the shipped AGNDC puts the face next to the low border +0.02 voxel out and the face next
to the high border +0.26; with 4 more empty points past the high border the high face moves to
+0.13 (surface nets: +0.10 on both) and the low face stays (docs/experiments/
thin-parts-routing.md). This scores that framing:

    .venv/bin/python research/high_margin.py DATA -o OUT --res 64 [--shifts 3] --extra 4
"""

from __future__ import annotations

import numpy as np
from stage_eval import eval_parser, run_eval_with_prediction


def main() -> None:
    parser = eval_parser(__doc__)
    parser.add_argument("--extra", type=int, default=4, help="empty points added past the "
                        "lattice's high end on every axis (a multiple of 4)")
    args = parser.parse_args()

    from agndc_core.methods import CHECKPOINT_NAMES

    def padded(method, lattice, predict):
        if method not in CHECKPOINT_NAMES or not args.extra:  # the learned methods only
            return predict(method, lattice)
        wide = np.pad(lattice, [(0, args.extra)] * 3)
        vertex = predict(method, wide)
        return np.ascontiguousarray(vertex[:lattice.shape[0], :lattice.shape[1],
                                           :lattice.shape[2]])

    run_eval_with_prediction(args, padded)

if __name__ == "__main__":
    main()
