"""The picture of docs/experiments/student.md: the demo's CAD part and a bevelled cube remeshed
by AGNDC and by its distilled version (``agndc_fast``), flat-shaded with edges.

    .venv/bin/python research/student_figure.py [-o docs/images/agndc_fast.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agndc_core.pipeline import remesh_mesh
    from agndc_core.study.report import _draw, save_small_png
    from agndc_core.study.shapes import bevelled_cube, cad_part

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--out", type=Path,
                        default=ROOT / "docs" / "images" / "agndc_fast.png")
    args = parser.parse_args()
    shapes = (("CAD part, 64 voxels", cad_part(7), 64), ("bevelled cube, 40 voxels",
                                                         bevelled_cube(), 40))
    fig = plt.figure(figsize=(8.0, 8.0), dpi=90)
    for row, (name, (vertices, faces), res) in enumerate(shapes):
        for col, method in enumerate(("agndc", "agndc_fast")):
            result = remesh_mesh(vertices, faces, resolution=res, method=method)
            ax = fig.add_subplot(2, 2, 2 * row + col + 1, projection="3d")
            _draw(ax, result.vertices, result.faces, np.asarray(vertices, float))
            ax.set_title(f"{method}: {name}", fontsize=9)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.95, wspace=0, hspace=0.05)
    save_small_png(fig, args.out)
    print(args.out)


if __name__ == "__main__":
    main()
