"""Small voxel models for the tests and figures: a coloured house (as MagicaVoxel art is drawn)
with the figure of its colours carried onto remeshed meshes (``docs/images/vox_colors_house.png``,
made by ``research/vox_colors_figure.py``), and a three-label volume (a segmentation's label
map)."""

from __future__ import annotations

import numpy as np

from ..colors import VoxelColors, face_colors
from ..grid import VoxelGrid

#: the house's palette entries (index: sRGB), written as the file's RGBA chunk
HOUSE_COLORS = {
    1: (96, 160, 72),    # lawn
    2: (236, 222, 190),  # walls
    3: (120, 72, 40),    # door
    4: (110, 170, 220),  # windows
    5: (178, 52, 44),    # roof
    6: (120, 120, 124),  # chimney
}
#: (title, method) of the figure's columns after the voxels
FIGURE_METHODS = (("marching cubes", "mc"), ("AGNDC", "agndc"))


def house_palette() -> np.ndarray:
    """(256, 4) uint8 sRGBA: ``HOUSE_COLORS``, other entries mid grey."""
    palette = np.full((256, 4), 128, dtype=np.uint8)
    palette[:, 3] = 255
    palette[0] = 0
    for index, rgb in HOUSE_COLORS.items():
        palette[index, :3] = rgb
    return palette


def house() -> VoxelGrid:
    """A 24 x 20 x 22 house (z up, as in MagicaVoxel) on a lawn: walls with a door and two
    windows on the front (-y) side, a gable roof along x and a chimney; six colours."""
    indices = np.zeros((24, 20, 22), dtype=np.uint8)
    indices[:, :, 0:2] = 1  # lawn
    indices[4:20, 4:16, 2:12] = 2  # walls (solid)
    indices[10:14, 4, 2:9] = 3  # door, in the front wall's outer layer
    for x0 in (5, 15):
        indices[x0:x0 + 4, 4, 6:10] = 4  # windows
    for level in range(7):  # gable roof: each layer one voxel narrower on both sides
        indices[3:21, 3 + level:17 - level, 12 + level] = 5
    indices[15:18, 11:14, 14:21] = 6  # chimney through the back slope
    return VoxelGrid(indices != 0, source="house.vox",
                     colors=VoxelColors(indices, house_palette()))


def render_house_figure(path, *, threads: int | None = None) -> dict:
    """The house's voxels, then its marching-cubes and AGNDC meshes with each face coloured by
    the nearest voxel (``colors.face_colors``), flat shaded; returns {method: (F,) indices}."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..pipeline import remesh

    grid = house()
    palette = grid.colors.palette[:, :3] / 255.0  # (256, 3)
    fig = plt.figure(figsize=(3.4 * (1 + len(FIGURE_METHODS)), 3.6), dpi=100)
    ax = fig.add_subplot(1, 1 + len(FIGURE_METHODS), 1, projection="3d")
    # ax.voxels draws voxel (i, j, k) over [i, i + 1]: shift by half a voxel to the centres
    ax.voxels(*np.indices(np.add(grid.shape, 1)) - 0.5, grid.occupancy,
              facecolors=palette[grid.colors.indices], edgecolor=(0, 0, 0, 0.15),
              linewidth=0.2, shade=True)
    _frame(ax, grid.shape, "voxels (.vox)")
    used = {}
    for col, (title, method) in enumerate(FIGURE_METHODS, start=2):
        result = remesh(grid, method=method, threads=threads)
        index = face_colors(result.vertices, result.faces, grid)
        used[method] = index
        ax = fig.add_subplot(1, 1 + len(FIGURE_METHODS), col, projection="3d")
        _draw_colored(ax, result.vertices, result.faces, palette[index])
        _frame(ax, grid.shape, f"{title}, {len(result.faces):,} faces")
    fig.subplots_adjust(left=0, right=1, bottom=0, top=0.92, wspace=0)
    _save_small_png(fig, path)
    plt.close(fig)
    return used


def _save_small_png(fig, path) -> None:
    """A 128-colour palette PNG: a third of the RGB file's bytes, the same picture to the eye
    (flat-shaded faces use few distinct colours)."""
    import io

    from PIL import Image

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png")
    buffer.seek(0)
    Image.open(buffer).convert("RGB").quantize(colors=128).save(path, optimize=True)


def _draw_colored(ax, vertices, faces, rgb):
    """Triangles in their (F, 3) colours, shaded by a head light (two-sided), thin edges."""
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    tri = vertices[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
    light = np.array([0.4, -0.7, 0.6]) / np.linalg.norm([0.4, -0.7, 0.6])
    shade = 0.45 + 0.55 * np.abs(normal @ light)  # (F,)
    ax.add_collection3d(Poly3DCollection(tri, facecolors=np.clip(shade[:, None] * rgb, 0, 1),
                                         edgecolors=(0, 0, 0, 0.12), linewidths=0.1))


def _frame(ax, shape, title):
    half = max(shape) * 0.45
    for setter, n in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), shape):
        setter((n - 1) / 2 - half, (n - 1) / 2 + half)
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=22, azim=-62)
    ax.set_axis_off()
    ax.set_title(title, fontsize=10)


def three_labels(shape=(40, 48, 36)) -> np.ndarray:
    """(X, Y, Z) int16 label map: a ball (1), a box (3) and a ring (7) apart, one voxel of -2
    (a negative value, background like 0)."""
    x, y, z = np.indices(shape, dtype=np.float64)
    values = np.zeros(shape, dtype=np.int16)
    values[(x - 12) ** 2 + (y - 14) ** 2 + (z - 12) ** 2 <= 8 ** 2] = 1
    values[24:34, 8:20, 6:30] = 3
    values[(np.hypot(x - 20, y - 34) - 8) ** 2 + (z - 20) ** 2 <= 3.2 ** 2] = 7
    values[0, 0, 0] = -2
    return values
