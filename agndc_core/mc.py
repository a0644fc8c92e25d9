"""Marching-cubes baseline on the same binary grid, in the same world coordinates.

The occupancy is padded into the dual-contouring lattice (grid.py) and contoured at level 0.5 by
scikit-image, so both methods see exactly the same samples and share one index -> world map.
"""

from __future__ import annotations

import numpy as np

from .grid import LATTICE_PAD, pad_to_lattice


def marching_cubes_lattice(lattice: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes of a padded (Dx, Dy, Dz) bool lattice.

    Returns:
        vertices: (V, 3) float64 lattice coordinates; faces: (F, 3) int64, facing outward.
    """
    from skimage.measure import marching_cubes

    if not lattice.any() or lattice.all():
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    # with inside = 1, "ascent" gives faces wound outward (checked by a signed-volume test)
    vertices, faces, _, _ = marching_cubes(lattice.astype(np.float32), level=0.5,
                                           gradient_direction="ascent", allow_degenerate=False)
    return vertices.astype(np.float64), faces.astype(np.int64)


def marching_cubes_grid(occupancy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Marching cubes of an (X, Y, Z) bool grid; vertices in voxel index coordinates."""
    vertices, faces = marching_cubes_lattice(pad_to_lattice(occupancy, levels=0))
    return vertices - LATTICE_PAD, faces
