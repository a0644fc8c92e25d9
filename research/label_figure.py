"""Render docs/images/labelmaps_three_labels.png: a generated 3-label volume read as one mask
(one mesh) and meshed per label (``agndc_core.labelmaps``, one colour per label).

    .venv/bin/python research/label_figure.py [--out docs/images/labelmaps_three_labels.png]

The volume (48 x 44 x 40 voxels of 1 x 1 x 1.5 units): a slab (label 3) with a ball (1) resting
on it and a ring (7) standing on it, each touching the slab, as neighbouring structures of a
segmentation touch.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from agndc_core.grid import VoxelGrid
from agndc_core.labelmaps import LabelMap, remesh_labels
from agndc_core.meshcheck import topology_violations
from agndc_core.pipeline import remesh

#: label -> face colour (RGB) of its mesh
COLOURS = {1: (0.85, 0.35, 0.3), 3: (0.35, 0.55, 0.85), 7: (0.4, 0.75, 0.4)}
GREY = (0.75, 0.78, 0.82)


def touching_labels(shape=(48, 44, 40)) -> np.ndarray:
    """(X, Y, Z) int16 label map: slab 3, ball 1 on it, ring 7 standing on it."""
    x, y, z = np.indices(shape, dtype=np.float64)
    values = np.zeros(shape, dtype=np.int16)
    values[4:44, 4:40, 3:11] = 3
    values[(x - 14) ** 2 + (y - 22) ** 2 + (z - 20) ** 2 <= 9.5 ** 2] = 1
    ring = (np.hypot(x - 33, z - 22) - 9) ** 2 + (y - 22) ** 2 <= 3.2 ** 2
    values[ring & (values == 0)] = 7
    return values


def _draw(ax, meshes, colours, frame):
    """Flat-shaded triangles of several (vertices, faces) meshes, one colour each."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    from agndc_core.study.report import frame_axes

    light = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])
    triangles, colors = [], []
    for (vertices, faces), colour in zip(meshes, colours):
        tri = vertices[faces]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
        shade = 0.3 + 0.7 * np.abs(normal @ light)
        triangles.append(tri)
        colors.append(np.clip(shade[:, None] * np.array(colour), 0, 1))
    ax.add_collection3d(Poly3DCollection(np.concatenate(triangles),
                                         facecolors=np.concatenate(colors),
                                         edgecolors="none"))
    frame_axes(ax, *frame, zoom=0.4, elev=22, azim=-65)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path,
                        default=Path("docs/images/labelmaps_three_labels.png"))
    args = parser.parse_args(argv)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    volume = LabelMap(touching_labels(), np.diag([1.0, 1.0, 1.5, 1.0]), source="three labels")
    merged = remesh(VoxelGrid(volume.values > 0, volume.affine), method="agndc")
    per_label = remesh_labels(volume, method="agndc")
    for label, result in per_label.items():
        defects = topology_violations(result.vertices, result.faces)
        print(f"label {label}: {volume.labels()[label]} voxels, {len(result.faces)} faces, "
              f"{result.seconds:.2f} s, closed 2-manifold: {not any(defects.values())}")
    print(f"one mask: {len(merged.faces)} faces")
    frame = (merged.vertices.min(0), merged.vertices.max(0))
    fig = plt.figure(figsize=(8.0, 3.6), dpi=80)
    ax = fig.add_subplot(1, 2, 1, projection="3d")
    _draw(ax, [(merged.vertices, merged.faces)], [GREY], frame)
    ax.set_title("read as one mask: 1 mesh", fontsize=10)
    ax = fig.add_subplot(1, 2, 2, projection="3d")
    _draw(ax, [(r.vertices, r.faces) for r in per_label.values()],
          [COLOURS[label] for label in per_label], frame)
    ax.set_title("per label: " + ", ".join(f"label {k}" for k in per_label), fontsize=10)
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92, wspace=0)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(args.out)
    plt.close(fig)
    print(f"written: {args.out} ({args.out.stat().st_size // 1024} KB)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
