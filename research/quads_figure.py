"""Render docs/images/quads.png: triangle output beside quad output (``RemeshResult.polygons``).

Rows: a generated CAD part (``study.shapes.cad_part(19)``) and a sphere; columns: the triangles
``remesh`` returns, then the same surface as quads (blue) and the triangles that stay (orange).
Prints the quad share of each row.

    python research/quads_figure.py [--res 32] [--method agndc] [--out docs/images/quads.png]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
QUAD_COLOUR = np.array([0.62, 0.74, 0.92])
TRIANGLE_COLOUR = np.array([0.98, 0.62, 0.25])
LIGHT = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])


def shapes():
    """(name, (V, 3) vertices, (F, 3) faces) of each row."""
    import trimesh

    from agndc_core.study.shapes import cad_part

    sphere = trimesh.creation.icosphere(5, 0.5)
    return [("CAD part", *cad_part(19)), ("sphere", sphere.vertices, sphere.faces)]


def draw(ax, vertices, polygons, colours, frame) -> None:
    """Flat-shaded polygons (a list of (k, 3) corner arrays) with their edges."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from agndc_core.study.report import frame_axes

    normals = np.array([np.cross(p[1] - p[0], p[-1] - p[0]) for p in polygons])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True) + 1e-12
    shade = 0.35 + 0.65 * np.abs(normals @ LIGHT)
    ax.add_collection3d(Poly3DCollection(polygons, facecolors=shade[:, None] * colours,
                                         edgecolors=(0.1, 0.1, 0.2, 0.6), linewidths=0.25))
    frame_axes(ax, frame.min(0), frame.max(0))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--res", type=int, default=32)
    parser.add_argument("--method", default="agndc")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "images" / "quads.png")
    args = parser.parse_args()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agndc_core.pipeline import remesh_mesh
    from agndc_core.study.report import save_small_png

    rows = shapes()
    fig = plt.figure(figsize=(7.0, 3.3 * len(rows)), dpi=90)
    for row, (name, vertices, faces) in enumerate(rows):
        result = remesh_mesh(np.asarray(vertices), np.asarray(faces), resolution=args.res,
                             method=args.method)
        polygons = result.polygons()
        v = result.vertices
        corners = [v[q] for q in polygons.quads] + [v[t] for t in polygons.triangles]
        colours = np.repeat([QUAD_COLOUR, TRIANGLE_COLOUR],
                            [len(polygons.quads), len(polygons.triangles)], axis=0)
        ax = fig.add_subplot(len(rows), 2, 2 * row + 1, projection="3d")
        draw(ax, v, list(v[result.faces]), np.tile(QUAD_COLOUR, (len(result.faces), 1)), v)
        ax.set_title(f"{name}: {len(result.faces):,} triangles", fontsize=9)
        ax = fig.add_subplot(len(rows), 2, 2 * row + 2, projection="3d")
        draw(ax, v, corners, colours, v)
        ax.set_title(f"--quads: {len(polygons.quads):,} quads, {len(polygons.triangles):,} "
                     f"triangles ({100 * polygons.quad_fraction:.0f} % quads)", fontsize=9)
        print(f"{name}: {len(result.faces)} triangles -> {len(polygons.quads)} quads + "
              f"{len(polygons.triangles)} triangles ({100 * polygons.quad_fraction:.1f} %)")
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.95, wspace=0, hspace=0.08)
    save_small_png(fig, args.out)
    plt.close(fig)
    print(f"written: {args.out} ({args.out.stat().st_size // 1024} KB)")


if __name__ == "__main__":
    main()
