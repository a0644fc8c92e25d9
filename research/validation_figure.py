"""Pictures of the validation family: marching cubes | surface nets | UNDC | AGNDC | ground truth.

One row per named shape of a folder written by ``agndc val-data`` (the grid alone, the shipped
weights, the same pipeline as ``agndc eval``):

    .venv/bin/agndc val-data -o runs/val2 -n 48
    .venv/bin/python research/validation_figure.py runs/val2 \\
        val_2000028 val_2000010 val_2000030 \\
        -o docs/images/validation_family.png

``--methods mc,agndc,agndc_fast`` draws other methods' columns (their menu names as titles).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from agndc_core.study.evaluate import find_meshes
from agndc_core.study.report import render_figure

COLUMNS = (("marching cubes", "mc", {}), ("surface nets", "surfacenets", {}),
           ("UNDC", "undc", {}), ("AGNDC", "agndc", {}), ("ground truth", None, {}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("folder", type=Path, help="a folder from `agndc val-data`")
    parser.add_argument("names", nargs="+", help="mesh file stems, one row each")
    parser.add_argument("-o", "--out", type=Path, required=True)
    parser.add_argument("--res", type=int, default=64)
    parser.add_argument("--methods", help="comma-separated methods instead of MC, surface nets, "
                        "UNDC and AGNDC")
    args = parser.parse_args()
    columns = COLUMNS
    if args.methods:
        from agndc_core.methods import title

        columns = tuple((title(m), m, {}) for m in args.methods.split(",")) + COLUMNS[-1:]
    # 48 colours: the grey-blue renders lose nothing visible and shrink ~5x
    if not render_figure(find_meshes(args.folder), args.names, args.out, resolution=args.res,
                         columns=columns, colours=48):
        raise SystemExit(f"none of {args.names} in {args.folder}")
    print(f"written: {args.out}")


if __name__ == "__main__":
    main()
