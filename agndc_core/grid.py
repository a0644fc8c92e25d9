"""The one binary-grid type of the project and the grid convention, written down once.

Convention (everything else in the package follows it)
------------------------------------------------------
* A **voxel** ``(i, j, k)`` of a ``VoxelGrid`` is a sample of the solid: ``occupancy[i, j, k]`` is
  True when the voxel's *centre* is inside the shape. Its centre sits at index coordinates
  ``(i, j, k)``; ``affine`` (4x4) maps index coordinates to world coordinates, so the world
  position of voxel centre ``(i, j, k)`` is ``affine @ (i, j, k, 1)``. For an axis-aligned grid,
  ``affine = diag(voxel_size, 1)`` with translation ``origin`` (the centre of voxel 0, 0, 0).
* **Dual-contouring lattice.** Voxel centres are the *grid points* of dual contouring. Before
  contouring, the occupancy is padded with ``LATTICE_PAD`` empty layers on the low side and at
  least one on the high side (rounded up so every dimension is a multiple of ``2**levels`` for
  the cascade), so the outer surface is always closed. Point ``p`` of the padded lattice is voxel
  ``p - LATTICE_PAD``.
* A **cell** ``c`` of the lattice spans points ``c`` .. ``c + 1`` (its min corner is point ``c``).
  Network outputs live on the padded lattice, one row per point, channel-first ``(6, Dx, Dy, Dz)``:
  channels 0..2 are the dual vertex of cell ``c`` as an offset in [0, 1]^3 from its min corner;
  channels 3..5 are the edge logits of the edges leaving point ``c`` along +x, +y, +z.
  The vertex of cell ``c`` therefore lies at index coordinates ``c + offset - LATTICE_PAD``.
* **Coarser scales** ``s`` of the cascade see the voxels pooled in 2x2x2 blocks (a coarse voxel is
  occupied if any of its 8 children is). Coarse point ``I`` of scale ``s`` sits at fine lattice
  coordinates ``2**s * I + (2**s - 1) / 2`` with spacing ``2**s`` (see ``scale_lattice``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .errors import GridError

if TYPE_CHECKING:
    from .colors import VoxelColors

LATTICE_PAD = 1  # empty layers added on the low side before contouring
#: the lattice is always padded for a cascade this deep (the paper's j = 2), whatever the method,
#: so every method and the labels see the same lattice
CASCADE_LEVELS = 2

#: For axis a, the two other axes in cyclic order (a quad around an a-edge listed in this order
#: faces +a).
OTHER_AXES = ((1, 2), (2, 0), (0, 1))
#: The 12 edges of a cell, written once: (axis, start), the edge leaving lattice point
#: ``cell + start`` along +axis. Edge 4 a + 2 db + dc starts at db e_b + dc e_c with
#: (b, c) = OTHER_AXES[a]. Labels, surface nets, the contour tables and the network's sparse
#: up-sampling all read the cell's edges from here.
CELL_EDGES = tuple(
    (axis, tuple(db if i == b else dc if i == c else 0 for i in range(3)))
    for axis, (b, c) in enumerate(OTHER_AXES) for db in (0, 1) for dc in (0, 1))

#: Largest grid the remesher accepts, in voxels (512^3 plus room for non-cubic shapes).
MAX_VOXELS = 600 * 600 * 600


@dataclass
class VoxelGrid:
    """A boolean voxel grid placed in world space.

    Attributes:
        occupancy: (X, Y, Z) bool, True where the voxel centre is inside the solid.
        affine: (4, 4) float64, index coordinates (voxel centres) -> world coordinates.
        source: free text naming where the grid came from (file name, mesh name), for messages.
        source_bounds: (2, 3) float64 world (min, max) corners of the bounding box of the mesh
            this grid was voxelised from (``voxelize`` sets it), or None for a grid that came
            as a grid. The grid alone cannot tell where an axis-aligned face lies inside its
            layer of voxels; for the faces that bound the mesh, these six numbers can
            (``flatpatches.snap_to_bounds``).
        colors: the palette index of each voxel and the palette (``colors.VoxelColors``, same
            shape as ``occupancy``), for a grid read from a coloured format (.vox); else None.
    """

    occupancy: np.ndarray
    affine: np.ndarray = field(default_factory=lambda: np.eye(4))
    source: str = "array"
    source_bounds: np.ndarray | None = None
    colors: VoxelColors | None = None

    def __post_init__(self) -> None:
        self.occupancy = as_occupancy(self.occupancy, name=self.source)
        affine = np.asarray(self.affine, dtype=np.float64)
        if affine.shape != (4, 4) or not np.all(np.isfinite(affine)):
            raise GridError(f"{self.source}: affine must be a finite 4x4 matrix, "
                            f"got {affine.shape}")
        if abs(np.linalg.det(affine[:3, :3])) < 1e-30:
            raise GridError(f"{self.source}: affine is singular (zero voxel size?)")
        self.affine = affine
        if self.source_bounds is not None:
            bounds = np.asarray(self.source_bounds, dtype=np.float64)
            if bounds.shape != (2, 3) or not np.all(np.isfinite(bounds)) \
                    or np.any(bounds[0] > bounds[1]):
                raise GridError(f"{self.source}: source_bounds must be finite (min, max) corners "
                                f"of shape (2, 3), got {bounds.tolist()}")
            self.source_bounds = bounds
        if self.colors is not None and self.colors.indices.shape != self.occupancy.shape:
            raise GridError(f"{self.source}: colour indices {self.colors.indices.shape} do not "
                            f"match the grid {self.occupancy.shape}")

    @classmethod
    def from_spacing(cls, occupancy, voxel_size=1.0, origin=(0.0, 0.0, 0.0), source="array",
                     source_bounds=None):
        """Build an axis-aligned grid: ``voxel_size`` scalar or (3,), ``origin`` = centre of
        voxel 0."""
        size = np.broadcast_to(np.asarray(voxel_size, dtype=np.float64), (3,))
        if np.any(~np.isfinite(size)) or np.any(size <= 0):
            raise GridError(f"{source}: voxel size must be positive and finite, got {size}")
        affine = np.eye(4)
        affine[:3, :3] = np.diag(size)
        affine[:3, 3] = np.asarray(origin, dtype=np.float64)
        return cls(occupancy, affine, source, source_bounds)

    @property
    def shape(self) -> tuple[int, int, int]:
        return tuple(self.occupancy.shape)

    @property
    def voxel_size(self) -> np.ndarray:
        """(3,) float64 length of one voxel step along each index axis, in world units."""
        return np.linalg.norm(self.affine[:3, :3], axis=0)

    @property
    def origin(self) -> np.ndarray:
        """(3,) float64 world position of the centre of voxel (0, 0, 0)."""
        return self.affine[:3, 3].copy()

    def index_to_world(self, points_nx3: np.ndarray) -> np.ndarray:
        """Map (N, 3) index coordinates (voxel centres at integers) to (N, 3) world coordinates."""
        return _apply_affine(points_nx3, self.affine)

    def world_to_index(self, points_nx3: np.ndarray) -> np.ndarray:
        """Inverse of ``index_to_world``."""
        points = np.asarray(points_nx3, dtype=np.float64).reshape(-1, 3)
        inverse = np.linalg.inv(self.affine)
        return points @ inverse[:3, :3].T + inverse[:3, 3]

    def check_not_trivial(self) -> None:
        """Raise GridError for a grid with no surface (all empty). A full grid is fine: padding
        closes it."""
        if not self.occupancy.any():
            raise GridError(f"{self.source}: the grid is empty (no occupied voxel), nothing to "
                            "mesh")


def as_occupancy(array, name: str = "array") -> np.ndarray:
    """Validate a user array and return it as a C-contiguous (X, Y, Z) bool copy.

    Accepts bool arrays and integer/float arrays holding only 0 and 1 (a common export format);
    anything else is refused with a GridError that names the problem.
    """
    try:
        grid = np.asarray(array)
    except Exception as exc:  # e.g. ragged nested lists
        raise GridError(f"{name}: cannot be read as an array ({exc})") from None
    if grid.ndim != 3:
        raise GridError(f"{name}: a voxel grid must be 3-D (X, Y, Z), got shape {grid.shape}")
    if min(grid.shape) < 1:
        raise GridError(f"{name}: the grid has a zero-length axis, shape {grid.shape}")
    if grid.size > MAX_VOXELS:
        raise GridError(
            f"{name}: grid {grid.shape} has {grid.size:,} voxels, more than the {MAX_VOXELS:,} "
            "this remesher handles in memory; downsample it first"
        )
    if grid.dtype == bool:
        return np.ascontiguousarray(grid)
    if grid.dtype.kind not in "uif":
        raise GridError(f"{name}: expected a boolean or 0/1 numeric grid, got dtype {grid.dtype}")
    values = np.unique(grid)
    if not np.all(np.isin(values, (0, 1))):
        shown = ", ".join(str(v) for v in values[:5])
        raise GridError(
            f"{name}: expected a binary grid (only 0 and 1), found values {shown}"
            f"{' ...' if values.size > 5 else ''}; threshold it first (e.g. grid > 0.5)"
        )
    return np.ascontiguousarray(grid != 0)


def pad_to_lattice(occupancy: np.ndarray, levels: int = CASCADE_LEVELS) -> np.ndarray:
    """Pad an (X, Y, Z) bool grid into the dual-contouring lattice.

    ``LATTICE_PAD`` empty layers go on the low side and at least one on the high side, more to
    make every dimension a multiple of ``2**levels`` (the cascade halves the lattice ``levels``
    times).

    Returns:
        (Dx, Dy, Dz) bool, where point p is voxel p - LATTICE_PAD.
    """
    multiple = 2**levels
    high = [
        (-(n + LATTICE_PAD + 1) % multiple) + 1 for n in occupancy.shape
    ]  # at least one empty layer
    return np.pad(occupancy, [(LATTICE_PAD, h) for h in high])


def scale_lattice(level: int) -> tuple[float, float]:
    """(offset, spacing) of scale ``level``'s points in fine lattice coordinates.

    Coarse point I of scale s sits at fine coordinate ``spacing * I + offset``.
    """
    spacing = float(2**level)
    return (spacing - 1.0) / 2.0, spacing


def crossed_edges(inside: np.ndarray) -> np.ndarray:
    """(D) bool -> (D, 3) bool: edge p -> p + e_axis joins an inside and an outside point."""
    edge = np.zeros(inside.shape + (3,), dtype=bool)
    edge[:-1, :, :, 0] = inside[:-1] != inside[1:]
    edge[:, :-1, :, 1] = inside[:, :-1] != inside[:, 1:]
    edge[:, :, :-1, 2] = inside[:, :, :-1] != inside[:, :, 1:]
    return edge


def surface_cells(edge: np.ndarray) -> np.ndarray:
    """(D, 3) bool edges -> (D) bool cells having any crossed edge among their 12.

    Cell c's x-edges start at c, c+e_y, c+e_z, c+e_y+e_z (likewise for y and z), so a crossed
    edge at point p marks the cells p, p - e_b, p - e_c, p - e_b - e_c for its two other axes.
    """
    cells = np.zeros(edge.shape[:3], dtype=bool)
    inner = tuple(n - 1 for n in edge.shape[:3])  # cells need their far corner
    for axis, start in CELL_EDGES:
        # cell c has the edge leaving point c + start along axis
        cells[:inner[0], :inner[1], :inner[2]] |= edge[
            start[0]:start[0] + inner[0], start[1]:start[1] + inner[1],
            start[2]:start[2] + inner[2], axis]
    return cells


def occupancy_pyramid(lattice: np.ndarray, levels: int) -> list[np.ndarray]:
    """[G_0, ..., G_levels]: the lattice and its OR-pooled coarser scales (``pool_occupancy``)."""
    grids = [np.asarray(lattice, dtype=bool)]
    for _ in range(levels):
        grids.append(pool_occupancy(grids[-1]))
    return grids


def lattice_to_world(points_nx3: np.ndarray, affine: np.ndarray) -> np.ndarray:
    """(N, 3) padded-lattice coordinates -> (N, 3) world coordinates (point p = voxel p - pad)."""
    return _apply_affine(np.asarray(points_nx3, dtype=np.float64) - LATTICE_PAD, affine)


def _apply_affine(points_nx3, affine) -> np.ndarray:
    """(N, 3) index coordinates -> (N, 3) world coordinates under a (4, 4) affine."""
    points = np.asarray(points_nx3, dtype=np.float64).reshape(-1, 3)
    affine = np.asarray(affine, dtype=np.float64)
    return points @ affine[:3, :3].T + affine[:3, 3]


def pool_occupancy(lattice: np.ndarray) -> np.ndarray:
    """(Dx, Dy, Dz) bool -> (Dx/2, Dy/2, Dz/2) bool: a coarse voxel is occupied if any child is."""
    dx, dy, dz = lattice.shape
    blocks = lattice.reshape(dx // 2, 2, dy // 2, 2, dz // 2, 2)
    return blocks.any(axis=(1, 3, 5))
