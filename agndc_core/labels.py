"""Ground-truth labels (UNDC style) from a mesh, at every scale of the cascade.

For each scale s the labels live on that scale's lattice (grid.py, ``scale_lattice``):

* ``inside``  (D,) bool     exact inside/outside of the true solid at the lattice points;
* ``edge``    (D, 3) bool   the edge leaving point p along +axis crosses the surface, i.e. its two
                            end points differ (the crossing parity, which is what a watertight
                            dual-contoured surface can represent);
* ``surface`` (D,) bool     cells with at least one crossed edge among their 12 edges;
* ``vertex``  (D, 3) float32 the dual vertex of each surface cell as an offset in [0, 1]^3 from
                            its min corner (0 elsewhere; masked from the loss by ``surface``).
* ``quadric`` (D, 6) float32 the mean of n n^T over the cell's surface samples (xx, yy, zz,
                            xy, yz, zx): (x - v)^T Q (x - v) is the mean squared distance of x to
                            the tangent planes through v, the part of a vertex error that moves
                            the surface (flat cells: along the normal only; creases: off the
                            crease; corners: every direction). The training loss weighs by it.

The vertex of a cell minimises the quadratic error of the planes of the true surface samples that
fall inside the cell (a QEF, as in dual contouring), solved with truncated eigenvalues about the
samples' mass point so flat and edge cells stay well posed; a solution outside the cell is pulled
back along the segment towards the mass point (UNDC grows a Tikhonov pull until the vertex is
inside, which has the same effect). Samples are deterministic (a low-discrepancy
sequence inside each triangle plus points along its edges, ``SAMPLES_PER_CELL`` per cell side)
and include every triangle's corners with that triangle's normal, so sharp corners and creases
are represented in the cells that hold them.

At scale 0 ``inside`` equals the voxelisation of the mesh (same rays, same frame), so the input
grid and the labels agree exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .grid import (  # noqa: F401  (lattice topology lives in grid.py; re-exported here)
    CASCADE_LEVELS,
    CELL_EDGES,
    LATTICE_PAD,
    VoxelGrid,
    crossed_edges,
    pad_to_lattice,
    scale_lattice,
    surface_cells,
)
from .tolerances import tol
from .voxelize import _choose_rule, check_mesh, inside_points

SAMPLES_PER_CELL = 4  # samples along one side of a finest-scale cell: 16 per cell of flat surface


@dataclass
class ScaleLabels:
    """Labels of one scale; all arrays share the lattice shape D = (Dx, Dy, Dz)."""

    inside: np.ndarray  # (D) bool
    edge: np.ndarray  # (D, 3) bool
    surface: np.ndarray  # (D) bool
    vertex: np.ndarray  # (D, 3) float32 in [0, 1]
    quadric: np.ndarray | None = None  # (D, 6) float32 mean n n^T (xx, yy, zz, xy, yz, zx)


def binary_oracle_vertex(labels: ScaleLabels, midpoints: np.ndarray) -> np.ndarray:
    """The oracle's vertices with what a binary grid cannot tell put back.

    A face that is exactly axis-aligned leaves the same voxels wherever it lies within its layer
    of cells, so no method that sees only the grid can know its depth: the estimate with the
    least error is the layer's midpoint, which is what surface nets gives along that axis. Cells
    on such faces (``tol.axis_aligned``) take ``midpoints``' coordinate along the face normal and
    keep the ground truth in the plane; every other cell keeps the ground truth. Contoured, this
    is an approximate ceiling for binary input: context can sometimes say more (the fixed frame
    ``voxelize`` puts around a mesh places its bounding box's low faces; a neighbouring slanted
    face's staircase places the edge it shares), so a method may beat it on some shapes.

    Args:
        labels: finest-scale labels with ``quadric``; midpoints: (D, 3) surface nets offsets of
            the same lattice (``surfacenets.surface_nets_lattice``).

    Returns:
        (D, 3) float32 offsets in [0, 1].
    """
    if labels.quadric is None:
        raise ValueError("binary_oracle_vertex needs labels with normal quadrics")
    return binary_visible_vertex(labels.vertex, labels.quadric, midpoints)


def binary_visible_vertex(vertex: np.ndarray, quadric: np.ndarray,
                          midpoints: np.ndarray) -> np.ndarray:
    """The rule of ``binary_oracle_vertex`` on plain arrays (also the trainer's
    ``--binary-targets``): where a cell's surface is exactly axis-aligned (its normal quadric's
    diagonal entry above ``tol.axis_aligned``) the coordinate along that axis is the midpoint's.

    Args:
        vertex: (..., 3) offsets; quadric: (..., 6) normal quadrics (``QUADRIC_ENTRIES``
            order); midpoints: (..., 3) surface nets offsets of the same cells.

    Returns:
        (..., 3) float32 offsets.
    """
    axis_aligned = quadric[..., :3] > tol.axis_aligned  # (..., 3): face normal along axis
    return np.where(axis_aligned, midpoints, vertex).astype(np.float32)


def make_labels(vertices, faces, grid: VoxelGrid, levels: int = 2,
                check=None) -> list[ScaleLabels]:
    """Labels of scales 0..levels for a mesh voxelised into ``grid``.

    Args:
        vertices: (V, 3) float world coordinates; faces: (F, 3) int.
        grid: the voxel grid (its affine places the lattice in world space).
        levels: number of coarser scales (the paper's j).
        check: called between the steps (and inside the ray casting), e.g. raises
            ``CancelledError`` when a run is cancelled.

    Returns:
        list of ScaleLabels, index = scale; scale s has lattice shape D0 / 2**s.
    """
    vertices, faces = check_mesh(vertices, faces)
    dims0 = np.array(pad_to_lattice(np.zeros(grid.shape, bool), max(levels, CASCADE_LEVELS)).shape)
    rule = _choose_rule(faces, "auto", check)
    # fine lattice coordinates: voxel index + pad
    fine = grid.world_to_index(vertices) + LATTICE_PAD
    labels = []
    for level in range(levels + 1):
        offset, spacing = scale_lattice(level)
        dims = tuple(int(d) for d in dims0 // 2**level)
        frame = (fine - offset) / spacing
        inside = inside_points(frame, faces, dims, rule=rule, check=check)
        edge = crossed_edges(inside)
        surface = surface_cells(edge)
        # sampled per scale, so coarse cells get the same sample density as fine ones
        points, normals = surface_samples(frame[faces], spacing=1.0 / SAMPLES_PER_CELL,
                                          check=check)
        if check is not None:
            check()
        vertex, quadric = cell_vertices(points, normals, surface, frame, faces, check)
        labels.append(ScaleLabels(inside, edge, surface, vertex, quadric))
    return labels


#: samples per chunk of ``surface_samples`` (about 100 bytes each in temporaries)
SAMPLE_CHUNK = 1 << 21


def surface_samples(triangles_fx3x3: np.ndarray, spacing: float,
                    check=None) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic samples of a triangle soup, about ``spacing`` apart, with face normals.

    Two kinds of samples, both per triangle and with that triangle's normal:
    * interior: ceil(area / spacing^2) points of the R2 low-discrepancy sequence folded into the
      triangle (even coverage whatever its shape; long slivers get few points);
    * boundary: points every ``spacing`` along each edge, starting at its first corner, so every
      corner and crease is sampled by all the faces that meet there.

    Triangles are sampled in chunks of about ``SAMPLE_CHUNK`` samples, ``check()`` before each;
    every sample depends on its own triangle only, so the chunks give the same arrays.

    Returns:
        points: (S, 3) float64; normals: (S, 3) float64 unit normals (degenerate faces dropped):
        every interior sample, then every boundary sample.
    """
    tri = np.asarray(triangles_fx3x3, dtype=np.float64)
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area2 = np.linalg.norm(cross, axis=1)
    keep = area2 > 1e-12
    tri, normal, area = tri[keep], cross[keep] / area2[keep, None], area2[keep] / 2
    count = np.ceil(area / spacing**2).astype(np.int64)  # interior samples of each triangle
    start, end = tri.reshape(-1, 3), tri[:, [1, 2, 0]].reshape(-1, 3)
    steps = np.maximum(np.ceil(np.linalg.norm(end - start, axis=1) / spacing), 1).astype(np.int64)
    per_triangle = np.cumsum(count + steps.reshape(-1, 3).sum(axis=1))
    total = int(per_triangle[-1]) if len(per_triangle) else 0
    cuts = np.searchsorted(per_triangle, np.arange(SAMPLE_CHUNK, total, SAMPLE_CHUNK)) + 1
    bounds = np.unique(np.concatenate([[0], cuts, [len(tri)]]))
    parts = []
    for lo, hi in zip(bounds[:-1], bounds[1:]):
        if check is not None:
            check()
        parts.append(_sample_triangles(tri[lo:hi], normal[lo:hi], count[lo:hi],
                                       start[3 * lo:3 * hi], end[3 * lo:3 * hi],
                                       steps[3 * lo:3 * hi]))
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3))
    interior, interior_normals, boundary, boundary_normals = zip(*parts)
    return (np.concatenate([*interior, *boundary]),
            np.concatenate([*interior_normals, *boundary_normals]))


def _sample_triangles(tri, normal, count, start, end, steps):
    """Interior points and normals, boundary points and normals of a chunk of triangles."""
    # interior: R2 sequence (golden ratios of the plastic number) in the unit square, folded
    owner, local = _enumerate(count)
    u = (0.5 + local * 0.7548776662466927) % 1.0
    v = (0.5 + local * 0.5698402909980532) % 1.0
    fold = u + v > 1
    u, v = np.where(fold, 1 - u, u), np.where(fold, 1 - v, v)
    t = tri[owner]
    interior = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    # boundary: along each edge a -> b, points at a + (i / m) (b - a), i = 0 .. m-1
    edge_owner, edge_local = _enumerate(steps)
    fraction = (edge_local / steps[edge_owner])[:, None]
    boundary = start[edge_owner] + fraction * (end - start)[edge_owner]
    return interior, normal[owner], boundary, normal[edge_owner // 3]


def _enumerate(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For counts (n,), the owner (sum,) and the index within its owner (sum,) of every item."""
    owner = np.repeat(np.arange(len(counts)), counts)
    local = np.arange(owner.size) - np.repeat(np.cumsum(counts) - counts, counts)
    return owner, local


#: (row, column) of the 6 stored entries of a symmetric 3x3 quadric
QUADRIC_ENTRIES = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (2, 0))


def cell_vertices(points, normals, surface, frame_vertices, faces, check=None):
    """QEF vertex and normal quadric of every surface cell.

    Args:
        points, normals: (S, 3) samples in the scale's lattice frame (points at integer corners).
        surface: (D) bool surface cells.
        frame_vertices, faces: the mesh in the same frame, for cells that got no sample.
        check: called between the steps and between batches of the sample-less cells'
            closest-point searches.

    Returns:
        vertex: (D, 3) float32 offsets in [0, 1] from each cell's min corner; quadric: (D, 6)
        float32 mean n n^T of the cell's samples (I / 3 for a cell no sample fell into). Both
        zero outside ``surface``.
    """
    # each step below is one pass over every sample (12M on a 3.1M-triangle mesh at 128³):
    # a check between them keeps the waits for Esc and for the progress bar short
    tick = check if check is not None else (lambda: None)
    dims = np.array(surface.shape)
    cell = np.floor(points).astype(np.int64)
    inside_box = np.all((cell >= 0) & (cell < dims), axis=1)
    tick()
    cell, points, normals = cell[inside_box], points[inside_box], normals[inside_box]
    flat = np.ravel_multi_index(cell.T, surface.shape)
    del cell
    tick()
    on_surface = surface.reshape(-1)[flat]
    flat, points, normals = flat[on_surface], points[on_surface], normals[on_surface]
    tick()
    # compact surface-cell ids so the accumulators are small
    surface_flat = np.flatnonzero(surface)
    slot = np.searchsorted(surface_flat, flat)
    corners = np.stack(np.unravel_index(surface_flat, surface.shape), axis=1).astype(np.float64)
    tick()
    position = _solve_qef(slot, points, normals, corners)
    tick()
    empty = np.isnan(position[:, 0])
    if np.any(empty):
        position[empty] = _closest_surface_points(corners[empty] + 0.5, frame_vertices, faces,
                                                  check)
    offsets = np.clip(position - corners, 0.0, 1.0)
    vertex = np.zeros(surface.shape + (3,), dtype=np.float32)
    vertex.reshape(-1, 3)[surface_flat] = offsets
    tick()
    count = np.bincount(slot, minlength=len(corners)).astype(np.float64)
    entries = np.stack([np.bincount(slot, normals[:, r] * normals[:, c], len(corners))
                        for r, c in QUADRIC_ENTRIES], axis=1)
    entries = np.where(count[:, None] > 0, entries / np.maximum(count, 1)[:, None],
                       np.array([1, 1, 1, 0, 0, 0]) / 3.0)
    quadric = np.zeros(surface.shape + (6,), dtype=np.float32)
    quadric.reshape(-1, 6)[surface_flat] = entries
    return vertex, quadric


def _solve_qef(slot, points, normals, corners) -> np.ndarray:
    """Per-cell QEF minimiser (n_cells, 3); NaN rows for cells without samples.

    Args:
        slot: (S,) int cell id of each sample; points, normals: (S, 3);
        corners: (n_cells, 3) float min corner of each cell.
    """
    n_cells = len(corners)
    count = np.bincount(slot, minlength=n_cells).astype(np.float64)
    mass = np.stack([np.bincount(slot, points[:, d], n_cells) for d in range(3)], axis=1)
    has = count > 0
    mass[has] /= count[has, None]
    # planes relative to the mass point: minimise sum (n . (x - m) - n . (p - m))^2
    rel = points - mass[slot]
    dist = np.einsum("sd,sd->s", normals, rel)
    ata = np.zeros((n_cells, 3, 3))
    atb = np.zeros((n_cells, 3))
    for r in range(3):
        atb[:, r] = np.bincount(slot, normals[:, r] * dist, n_cells)
        for c in range(r, 3):
            ata[:, r, c] = ata[:, c, r] = np.bincount(slot, normals[:, r] * normals[:, c], n_cells)
    ata += tol.qef_pull * np.trace(ata, axis1=1, axis2=2)[:, None, None] * np.eye(3)
    eigval, eigvec = np.linalg.eigh(ata)  # ascending eigenvalues
    keep = eigval > tol.qef_singular * eigval[:, 2:3]
    inverse = np.where(keep, 1.0 / np.where(keep, eigval, 1.0), 0.0)
    projected = np.einsum("ndk,nd->nk", eigvec, atb) * inverse
    position = mass + np.einsum("ndk,nk->nd", eigvec, projected)
    position = _pull_into_cells(position, mass, corners)
    position[~has] = np.nan
    return position


def _pull_into_cells(position, mass, corner) -> np.ndarray:
    """Move each position along the segment from its mass point until it lies in its cell."""
    lo, hi = corner - tol.cell_slack, corner + 1 + tol.cell_slack
    step = position - mass
    with np.errstate(divide="ignore", invalid="ignore"):
        limit_hi = np.where(step > 0, (hi - mass) / step, np.inf)
        limit_lo = np.where(step < 0, (lo - mass) / step, np.inf)
    t = np.clip(np.minimum(limit_hi, limit_lo).min(axis=1), 0.0, 1.0)
    t = np.nan_to_num(t, nan=0.0)
    return mass + step * t[:, None]


#: cells around a query cell whose triangles may hold its closest point: the query is a
#: surface cell's centre and the surface crosses that cell, so the closest point lies within
#: sqrt(3)/2 of it, well inside the next ring of cells (1.5 from the centre)
NEAR_CELLS = 1


#: sample-less cells per batch of closest-point queries: a batch of nearby cells searches a slab
#: of the mesh (``near_triangles``), and a cancellation check runs between batches
QUERY_CHUNK = 256


def _closest_surface_points(queries, frame_vertices, faces, check=None) -> np.ndarray:
    """(Q, 3) closest points on the mesh to surface-cell centres ``queries`` (lattice frame);
    used only for the rare cells no sample fell into. Queries go in batches of nearby cells
    (sorted by position), each searching only the triangles that can hold its points
    (``near_triangles``): a spatial tree of all of a dense mesh's triangles took 10 s to build
    and could not be cancelled."""
    import trimesh  # only needed on this rare path

    triangles = frame_vertices[faces]  # (F, 3, 3)
    boxes = np.floor(triangles.min(axis=1)), np.floor(triangles.max(axis=1))  # (F, 3) each
    candidates = near_triangles(queries, *boxes)
    # triangles wider than a ring go to every batch (a dense mesh has few); the others by the
    # box's low x, so a batch's candidates are one slice of them (a box spans <= 2 rings)
    wide = np.any(boxes[1] - boxes[0] > 2 * NEAR_CELLS, axis=1)
    small = np.flatnonzero(candidates & ~wide)
    small = small[np.argsort(boxes[0][small, 0], kind="stable")]
    low_x, wide = boxes[0][small, 0], np.flatnonzero(candidates & wide)
    order = np.lexsort(np.floor(queries).T[::-1])  # x-major: a batch covers a slab
    closest = np.empty_like(queries, dtype=np.float64)
    for a in range(0, len(order), QUERY_CHUNK):
        if check is not None:
            check()
        batch = order[a:a + QUERY_CHUNK]
        x = np.floor(queries[batch, 0])
        first = np.searchsorted(low_x, x.min() - 3 * NEAR_CELLS, side="left")
        last = np.searchsorted(low_x, x.max() + NEAR_CELLS, side="right")
        reach = np.concatenate([wide, small[first:last]])
        near = reach[near_triangles(queries[batch], boxes[0][reach], boxes[1][reach])]
        if len(near) == 0:  # not surface cells after all: search the whole mesh
            near = np.arange(len(faces))
        mesh = trimesh.Trimesh(frame_vertices, faces[np.sort(near)], process=False)
        closest[batch] = trimesh.proximity.closest_point(mesh, queries[batch])[0]
    return closest


def near_triangles(queries, box_lo, box_hi, rings: int = NEAR_CELLS) -> np.ndarray:
    """(F,) bool: triangles whose cell box (``box_lo``, ``box_hi``: (F, 3) floor of their
    corners' min and max, lattice frame) reaches a cell within ``rings`` cells (Chebyshev) of a
    query's cell. A box no wider than ``2 rings`` cells meets such a block of ``2 rings + 1``
    cells only with one of its corners inside, so small triangles are tested by their box's 8
    corners; wider ones are always kept."""
    cells = np.floor(queries).astype(np.int64)  # (Q, 3)
    origin = cells.min(axis=0) - rings
    shape = cells.max(axis=0) + rings - origin + 1
    marked = np.zeros(shape, dtype=bool)
    for offset in np.ndindex(*(2 * rings + 1,) * 3):  # (2 rings + 1)^3 shifts, not per query
        index = cells - origin + np.asarray(offset) - rings
        marked[index[:, 0], index[:, 1], index[:, 2]] = True
    near = np.any(box_hi - box_lo > 2 * rings, axis=1)
    for corner in np.ndindex(2, 2, 2):
        point = np.where(np.array(corner, dtype=bool), box_hi, box_lo).astype(np.int64) - origin
        inside = np.all((point >= 0) & (point < shape), axis=1)
        near[inside] |= marked[tuple(point[inside].T)]
    return near
