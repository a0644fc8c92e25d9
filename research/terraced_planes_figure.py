"""The picture of docs/experiments/terraced-planes.md: a box tilted 2° off an axis, remeshed
by AGNDC without and with the terraced-plane fit (``flatpatches.fit_terraced_planes``),
flat-shaded so that a wavy face shows its bands.

    .venv/bin/python research/terraced_planes_figure.py [--res 48] [-o PNG]
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
    import trimesh

    from agndc_core import pipeline
    from agndc_core.study.report import _draw, save_small_png

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=48)
    parser.add_argument("-o", "--out", type=Path,
                        default=ROOT / "docs" / "images" / "terraced_planes.png")
    args = parser.parse_args()
    box = trimesh.creation.box((1.0, 0.8, 0.5))
    box.apply_transform(trimesh.transformations.rotation_matrix(np.radians(2.0), [1, 0.3, 0]))
    fig = plt.figure(figsize=(8.0, 4.2), dpi=90)
    for col, (title, fit) in enumerate((("AGNDC, terraces as the network left them", False),
                                        ("AGNDC with the terraced-plane fit", True))):
        pipeline.TERRACED_PLANES = fit
        result = pipeline.remesh_mesh(box.vertices, box.faces, resolution=args.res)
        ax = fig.add_subplot(1, 2, col + 1, projection="3d")
        _draw(ax, result.vertices, result.faces, np.asarray(box.vertices))
        ax.view_init(elev=55, azim=-70)
        ax.set_title(title, fontsize=9)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92, wspace=0)
    save_small_png(fig, args.out)
    print(args.out)


if __name__ == "__main__":
    main()
