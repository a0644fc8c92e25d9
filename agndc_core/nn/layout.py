"""Band layout shared by both inference runtimes (torch ``band_ops.py``, numpy ``runtime/``).

Plain numpy and scipy, no torch: which lattice points form the band of a scale, the far-field
period of each scale, how far a snake reaches, which radii CRPM's stages need, and the cell
geometry (corners, edges, kernel offsets) every spatial op is written against. The torch path
builds its tensors from these arrays, so the two runtimes read one definition.
"""

from __future__ import annotations

import itertools
import math

import numpy as np
from scipy import ndimage

from ..grid import CELL_EDGES

#: (8, 3) the corners {0,1}^3 of a cell, index = 4 dx + 2 dy + dz
CELL_CORNERS = np.array(list(itertools.product((0, 1), repeat=3)), dtype=np.int64)
#: for each edge axis, the 4 corners (indices into CELL_CORNERS) its cell edges leave from:
#: x-edges leave from (0, dy, dz), y-edges from (dx, 0, dz), z-edges from (dx, dy, 0)
CELL_EDGE_CORNERS = tuple(
    tuple(sorted(4 * start[0] + 2 * start[1] + start[2] for a, start in CELL_EDGES if a == axis))
    for axis in range(3))
#: the 4 lateral corners of a snake tap's bilinear sample, (db, dc) in the order of the weights
SNAKE_CORNERS = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=np.int64)


class BandRows:
    """The row bookkeeping both runtimes' band classes share (``Band``, ``BandOps``): rows
    ``[0, T)`` are the torus, then the band points nearest first, so a band of smaller radius is
    a prefix. Subclasses set ``radius``, ``counts`` (rows of each radius 0..radius) and
    ``_radius_of_rows`` (row count -> radius)."""

    radius: int
    counts: list

    def radius_of(self, x) -> int:
        """The radius a row tensor was computed on, from its row count."""
        try:
            return self._radius_of_rows[x.shape[0]]
        except KeyError:
            raise ValueError(f"{x.shape[0]} rows is no band of this lattice "
                             f"(row counts {self.counts})") from None

    def rows(self, radius: int) -> int:
        return self.counts[min(radius, self.radius)]

    def crop(self, x, radius: int):
        return x[:self.rows(radius)]


def relative_position_index(window: int) -> np.ndarray:
    """(w^3, w^3) index into an LWSA block's ``(2w - 1)^3`` relative position bias table of the
    offset between tokens i and j (tokens in C order inside a window, as ``windows`` gathers)."""
    span = 2 * window - 1
    axis = np.arange(window)
    pos = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    rel = pos[:, None, :] - pos[None, :, :] + window - 1
    return (rel[..., 0] * span + rel[..., 1]) * span + rel[..., 2]


def cube_offsets(k: int) -> np.ndarray:
    """(k^3, 3) int64 neighbour offsets of a k x k x k kernel, in ``nn.Conv3d`` weight order."""
    r = range(-(k // 2), k // 2 + 1)
    return np.array(list(itertools.product(r, r, r)), dtype=np.int64)


def lateral_axes(axis: int) -> tuple[int, int]:
    """The two axes a snake along ``axis`` may bend into, in increasing order."""
    return tuple(a for a in range(3) if a != axis)


def surface_distance(occupancy: np.ndarray) -> np.ndarray:
    """(X, Y, Z) bool -> int32 Chebyshev distance to the nearest point of the other type.

    Points with a differing neighbour among their 26 get 1; borders replicate. A uniform grid
    gets a large value everywhere.
    """
    occ = occupancy.astype(np.uint8)
    surface = ndimage.maximum_filter(occ, 3, mode="nearest") != ndimage.minimum_filter(
        occ, 3, mode="nearest")
    if not surface.any():
        return np.full(occ.shape, np.iinfo(np.int32).max // 2, dtype=np.int32)
    return ndimage.distance_transform_cdt(~surface, metric="chessboard").astype(np.int32) + 1


def half_band(occupancy: np.ndarray, dist: np.ndarray, radius: int):
    """CRPM's half lattice of a scale: (coarse occupancy, coarse distance, coarse radius).

    A coarse point is near the surface if one of its 8 children is (ceil of the children's
    minimum distance / 2), so every fine band point's block mean and up-sampled parent are band
    rows, even where OR-pooling closes thin gaps; the radius covers what CRPM reads.
    """
    dx, dy, dz = dist.shape
    coarse = occupancy.reshape(dx // 2, 2, dy // 2, 2, dz // 2, 2).any(axis=(1, 3, 5))
    child_min = dist.reshape(dx // 2, 2, dy // 2, 2, dz // 2, 2).min(axis=(1, 3, 5))
    return coarse, (child_min + 1) // 2, (radius + 1) // 2 + 3


def torus_periods(levels: int, window: int | None) -> list[int]:
    """Far-field period P_s of every scale s = 0..levels.

    The coarsest scale is uniform far away (period 1), but CRPM of the next finer scale keeps
    half-resolution features there whose period is half of that scale's: P_j = window / 2 when
    attention makes the finer scale window-periodic. Each finer scale doubles the period (the
    sparse up-sampling depends on the child index), which stays a multiple of the window.
    """
    periods = [max(1, (window or 2) // 2)]
    for _ in range(levels):
        periods.insert(0, 2 * periods[0])
    return periods


def snake_margin(kernel: int, scope: float) -> int:
    """Lattice points a snake may reach beyond its centre: K // 2 along its axis, the bounded
    cumulative drift (+1 for the bilinear corner) across."""
    return max(kernel // 2, math.ceil(scope * (kernel // 2)) + 1) + 1


def lookup_margin(kernel: int, scope: float, window: int) -> int:
    """How far outside a lattice the lookups of one scale may reach without clamping."""
    return max(snake_margin(kernel, scope), window) + 1


def crpm_radii(radius: int) -> dict:
    """Band radii of CRPM's stages for an output of ``radius``, so that no read leaves what was
    computed (before capping by the band): mix convs, F^1/F^2, half-res stages, its input."""
    r_f = radius + 2
    r_h = (r_f + 1) // 2  # half rows holding the parents of F^1's rows
    r_down = r_h + 3
    r_f1 = max(r_f, 2 * r_down + 1)  # fine rows holding the children of r_down's rows
    return {"mix": radius + 1, "f": r_f, "half": r_h, "down": r_down, "f1": r_f1,
            "input": r_f1 + 1}
