"""Empty space past the shape's high end: ``agndc eval`` with every learned method run with
``--margin`` empty lattice points after the lattice's high end (``methods.Method.high_margin``,
passed to ``inference.predict_lattice``; the prediction is cropped back).

Training samples are voxelised meshes framed by ``pad_to_lattice``: one empty voxel and one
lattice layer before the shape, one empty voxel and 0-3 layers after it. On a plate 2.5 voxels
thick AGNDC without the margin puts the face next to the low border +0.02 voxel out and the face
next to the high border +0.26; with 4 more empty points past the high border the high face moves
to +0.13 (surface nets: +0.10 on both) and the low face stays (docs/experiments/
high-border-margin.md). AGNDC ships with 4, UNDC and ``agndc_fast`` with none; this scores any
one margin for all three (0: the framing before it):

    .venv/bin/python research/high_margin.py DATA -o OUT --res 64 [--shifts 3] --margin 0
"""

from __future__ import annotations

from dataclasses import replace

from stage_eval import eval_parser, run_eval


def main() -> None:
    parser = eval_parser(__doc__)
    parser.add_argument("--margin", type=int, default=4, help="empty points after the lattice's "
                        "high end on every axis, for every learned method (a multiple of 4 keeps "
                        "the pooling phase)")
    args = parser.parse_args()

    from agndc_core import methods

    for name in methods.CHECKPOINT_NAMES:  # the registry the pipeline reads the margin from
        methods.BY_NAME[name] = replace(methods.BY_NAME[name], high_margin=args.margin)
    run_eval(args)


if __name__ == "__main__":
    main()
