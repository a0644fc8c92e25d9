"""Pictures of remeshed shapes: marching cubes | surface nets | UNDC | AGNDC | ground truth.

One row per named shape of a mesh folder, or a synthetic shape of ``report.SYNTHETIC_SHAPES``
(the grid alone, the shipped weights, the same pipeline as ``agndc eval``; the columns of the
report's picture). The validation family, and the dev meshes' picture in ``docs/results.md``:

    .venv/bin/agndc val-data -o runs/val2 -n 48
    .venv/bin/python research/validation_figure.py runs/val2 \\
        val_2000028 val_2000010 val_2000030 \\
        -o docs/images/validation_family.png
    .venv/bin/python research/validation_figure.py ../shared/data/dev --report-shapes \\
        -o docs/results_shapes.png

``--methods mc,agndc,agndc_fast`` draws other methods' columns (their menu names as titles).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from agndc_core.study.evaluate import find_meshes
from agndc_core.study.report import (
    FIGURE_COLOURS,
    FIGURE_COLUMNS,
    FIGURE_SHAPES,
    figure_caption,
    render_figure,
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a folder of meshes (e.g. from `agndc val-data`)")
    parser.add_argument("names", nargs="*", help="mesh file stems, one row each")
    parser.add_argument("--report-shapes", action="store_true",
                        help="the rows of `agndc report`'s picture (report.FIGURE_SHAPES)")
    parser.add_argument("-o", "--out", type=Path, required=True)
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--methods", help="comma-separated methods instead of MC, surface nets, "
                        "UNDC and AGNDC")
    args = parser.parse_args()
    names = list(FIGURE_SHAPES) if args.report_shapes else args.names
    if not names:
        parser.error("name shapes, or pass --report-shapes")
    columns = FIGURE_COLUMNS
    if args.methods:
        from agndc_core.methods import title

        columns = tuple((title(m), m, {}) for m in args.methods.split(",")) + FIGURE_COLUMNS[-1:]
    if not render_figure(find_meshes(args.folder), names, args.out, resolution=args.res,
                         columns=columns, colours=FIGURE_COLOURS):
        raise SystemExit(f"none of {names} in {args.folder}")
    print(f"written: {args.out}")
    if not args.methods:
        print(f"caption: {figure_caption(args.res, names)}")


if __name__ == "__main__":
    main()
