"""Ground-truth labels (UNDC style) from a mesh, at every scale of the cascade.

For each scale s the labels live on that scale's lattice (grid.py, ``scale_lattice``):

* ``inside``  (D,) bool     exact inside/outside of the true solid at the lattice points;
* ``edge``    (D, 3) bool   the edge leaving point p along +axis crosses the surface, i.e. its two
                            end points differ (the crossing parity, which is what a watertight
                            dual-contoured surface can represent);
* ``surface`` (D,) bool     cells with at least one crossed edge among their 12 edges;
* ``vertex``  (D, 3) float32 the dual vertex of each surface cell as an offset in [0, 1]^3 from
                            its min corner (0 elsewhere; masked from the loss by ``surface``).
* ``quadric`` (D, 6) float32 the mean of n n^T over the cell's surface data (xx, yy, zz,
                            xy, yz, zx): (x - v)^T Q (x - v) is the mean squared distance of x to
                            the tangent planes through v, the part of a vertex error that moves
                            the surface (flat cells: along the normal only; creases: off the
                            crease; corners: every direction). The training loss weighs by it.

The vertex of a cell minimises the quadratic error of the planes of the true surface points of
the cell (a QEF, as in dual contouring): the exact crossings of its 12 edges (the Hermite data of
dual contouring, from the same rays as ``inside``) and deterministic samples of the surface
inside it (a low-discrepancy sequence inside each triangle plus points along its edges,
``SAMPLES_PER_CELL`` per cell side, so every triangle's corners and creases are represented in
the cells that hold them), each with its triangle's normal. The crossings give every surface
cell data, and every plane that crosses the cell's edges a weight of its own however little of
the cell it covers, so a crease or corner that only clips a cell still draws its vertex. The QEF
is solved with truncated eigenvalues about the data's mass point, so flat and edge cells stay
well posed; a solution outside the cell is replaced by the QEF's minimum over the cell (on a
crease that leaves the cell, the point of the crease inside it). A surface cell left without
data takes the surface point closest to its centre (rare: the other axes' rays outvoted its
edges' crossings).

At scale 0 ``inside`` equals the voxelisation of the mesh (same rays, same frame), so the input
grid and the labels agree exactly.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from .grid import (  # noqa: F401  (lattice topology lives in grid.py; re-exported here)
    CASCADE_LEVELS,
    CELL_EDGES,
    LATTICE_PAD,
    OTHER_AXES,
    VoxelGrid,
    crossed_edges,
    pad_to_lattice,
    scale_lattice,
    surface_cells,
)
from .tolerances import tol
from .voxelize import (
    TRIANGLE_CHUNK,
    _choose_rule,
    check_mesh,
    chunk_runs,
    inside_from_crossings,
    lattice_crossings,
    ray_jitter,
    triangle_chunks,
    triangle_cross,
)

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
        check: called between the steps and between the chunks of each (ray casting,
            sampling, the cells' sums and QEFs), e.g. raises ``CancelledError`` when a run is
            cancelled.

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
        # one ray casting gives the inside points and the exact edge crossings
        crossings = lattice_crossings(frame, faces, dims, check)
        inside = inside_from_crossings(crossings, dims, rule)
        edge = crossed_edges(inside)
        surface = surface_cells(edge)
        vertex, quadric = cell_vertices(frame, faces, crossings, surface, check)
        labels.append(ScaleLabels(inside, edge, surface, vertex, quadric))
    return labels


#: samples per chunk of the sampling and of the cells' sums (about 100 bytes each in
#: temporaries)
SAMPLE_CHUNK = 1 << 19


def surface_samples(vertices, faces, spacing: float,
                    check=None) -> tuple[np.ndarray, np.ndarray]:
    """Deterministic samples of a triangle mesh, about ``spacing`` apart, with face normals.

    Two kinds of samples, both per triangle and with that triangle's normal:
    * interior: ceil(area / spacing^2) points of the R2 low-discrepancy sequence folded into the
      triangle (even coverage whatever its shape; long slivers get few points);
    * boundary: points every ``spacing`` along each edge, starting at its first corner, so every
      corner and crease is sampled by all the faces that meet there.

    Returns:
        points: (S, 3) float64; normals: (S, 3) float64 unit normals (degenerate faces dropped):
        every interior sample, then every boundary sample (``sample_chunks`` in one piece).
    """
    parts = list(sample_chunks(vertices, faces, spacing, check))
    if not parts:
        return np.zeros((0, 3)), np.zeros((0, 3))
    interior, interior_normals, boundary, boundary_normals = zip(*parts)
    return (np.concatenate([*interior, *boundary]),
            np.concatenate([*interior_normals, *boundary_normals]))


def sample_chunks(vertices, faces, spacing: float, check=None):
    """``surface_samples`` in chunks: yields (interior points, their normals, boundary points,
    their normals) of consecutive runs of triangles holding about ``SAMPLE_CHUNK`` samples (at
    most ``TRIANGLE_CHUNK`` triangles), ``check()`` before each, after a first pass that counts
    each triangle's samples in chunks of ``TRIANGLE_CHUNK`` triangles (``check()`` before
    each). Every sample depends on its own triangle only, so any chunk sizes give the same
    samples."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    per_triangle = np.empty(len(faces), dtype=np.int64)
    for lo, triangles in triangle_chunks(vertices, faces, check):
        _, _, count, steps = _triangle_layout(triangles, spacing)
        per_triangle[lo:lo + len(triangles)] = count + steps.sum(axis=1)
    for lo, hi in chunk_runs(per_triangle, SAMPLE_CHUNK, TRIANGLE_CHUNK):
        if check is not None:
            check()
        yield _sample_triangles(vertices[faces[lo:hi]], spacing)


def _triangle_layout(triangles, spacing):
    """Per triangle: unit normal (F, 3), area (F,), interior samples (F,) and samples along
    each of its edges (F, 3); degenerate triangles get no samples at all."""
    cross = triangle_cross(triangles)
    area2 = np.linalg.norm(cross, axis=1)
    keep = area2 > 1e-12
    normal = cross / np.where(keep, area2, 1.0)[:, None]
    area = area2 / 2
    count = np.where(keep, np.ceil(area / spacing**2), 0).astype(np.int64)
    length = np.linalg.norm(triangles[:, [1, 2, 0]] - triangles, axis=2)  # (F, 3)
    steps = np.maximum(np.ceil(length / spacing), 1).astype(np.int64) * keep[:, None]
    return normal, area, count, steps


def _sample_triangles(triangles, spacing):
    """Interior points and normals, boundary points and normals of a chunk of triangles."""
    normal, _, count, steps = _triangle_layout(triangles, spacing)
    # interior: R2 sequence (golden ratios of the plastic number) in the unit square, folded
    owner, local = _enumerate(count)
    u = (0.5 + local * 0.7548776662466927) % 1.0
    v = (0.5 + local * 0.5698402909980532) % 1.0
    fold = u + v > 1
    u, v = np.where(fold, 1 - u, u), np.where(fold, 1 - v, v)
    t = triangles[owner]
    interior = t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])
    # boundary: along each edge a -> b, points at a + (i / m) (b - a), i = 0 .. m-1
    start, end = triangles.reshape(-1, 3), triangles[:, [1, 2, 0]].reshape(-1, 3)
    steps = steps.reshape(-1)
    edge_owner, edge_local = _enumerate(steps)
    fraction = (edge_local / np.maximum(steps, 1)[edge_owner])[:, None]
    boundary = start[edge_owner] + fraction * (end - start)[edge_owner]
    return interior, normal[owner], boundary, normal[edge_owner // 3]


def _enumerate(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For counts (n,), the owner (sum,) and the index within its owner (sum,) of every item."""
    owner = np.repeat(np.arange(len(counts)), counts)
    local = np.arange(owner.size) - np.repeat(np.cumsum(counts) - counts, counts)
    return owner, local


#: (row, column) of the 6 stored entries of a symmetric 3x3 quadric
QUADRIC_ENTRIES = ((0, 0), (1, 1), (2, 2), (0, 1), (1, 2), (2, 0))
#: the sums over a cell's samples that its QEF and quadric need, with p a sample's position
#: relative to the cell's min corner and n its unit normal: the count, p (3), n n^T (6, in
#: ``QUADRIC_ENTRIES`` order), n (n . p) (3)
CELL_SUMS = 13
#: every sample adds its terms to the sums rounded to multiples of 1 / SUM_SCALE: sums of such
#: numbers are exact in float64 (below 2^53, i.e. up to 4M samples in one cell), so the sums, and
#: the vertices, are the same however the samples are split into chunks or ordered
SUM_SCALE = 2.0**30
#: surface cells per chunk of the QEF solve (an eigendecomposition each, ~1 KB of temporaries)
CELL_CHUNK = 1 << 16


def cell_vertices(frame_vertices, faces, crossings, surface, check=None):
    """QEF vertex and normal quadric of every surface cell.

    A cell's data are the surface samples that fall inside it (``surface_samples``, spacing
    1 / ``SAMPLES_PER_CELL``) and the exact crossings of its 12 edges (``lattice_crossings``;
    each belongs to the 4 cells around its edge), each a point with its triangle's normal.
    The crossings give every surface cell data, and every plane that crosses a cell's edges a
    say in its QEF however little of the cell's area it covers: a crease or a corner that
    only clips a cell is still where that cell's vertex goes.

    Args:
        frame_vertices, faces: the mesh in the scale's lattice frame (points at integer corners).
        crossings: the three axes' ``Crossings`` of the same mesh and lattice.
        surface: (D) bool surface cells.
        check: called between the chunks of samples, crossings and cells, and between batches
            of the closest-point searches of cells that got no data.

    Returns:
        vertex: (D, 3) float32 offsets in [0, 1] from each cell's min corner; quadric: (D, 6)
        float32 mean n n^T of the cell's data (I / 3 for a cell that got none). Both zero
        outside ``surface``.
    """
    surface_flat = np.flatnonzero(surface)
    sums = np.zeros((len(surface_flat), CELL_SUMS))
    for interior, interior_normals, boundary, boundary_normals in sample_chunks(
            frame_vertices, faces, 1.0 / SAMPLES_PER_CELL, check):
        for points, normals in ((interior, interior_normals), (boundary, boundary_normals)):
            _add_to_cells(sums, surface, surface_flat, np.floor(points).astype(np.int64),
                          points, normals)
    for cells, points, normals in _crossing_samples(frame_vertices, faces, crossings, check):
        _add_to_cells(sums, surface, surface_flat, cells, points, normals)
    sums /= SUM_SCALE
    corners = np.stack(np.unravel_index(surface_flat, surface.shape), axis=1)
    offsets = np.empty((len(surface_flat), 3))
    for lo in range(0, len(surface_flat), CELL_CHUNK):
        if check is not None:
            check()
        offsets[lo:lo + CELL_CHUNK] = _solve_qef(sums[lo:lo + CELL_CHUNK])
    empty = np.isnan(offsets[:, 0])
    if np.any(empty):  # a crossing missed by the vote of the three axes' rays: rare
        offsets[empty] = _closest_surface_points(corners[empty] + 0.5, frame_vertices, faces,
                                                 check) - corners[empty]
    vertex = np.zeros(surface.shape + (3,), dtype=np.float32)
    vertex.reshape(-1, 3)[surface_flat] = np.clip(offsets, 0.0, 1.0)
    count = sums[:, :1]
    entries = np.where(count > 0, sums[:, 4:10] / np.maximum(count, 1),
                       np.array([1, 1, 1, 0, 0, 0]) / 3.0)
    quadric = np.zeros(surface.shape + (6,), dtype=np.float32)
    quadric.reshape(-1, 6)[surface_flat] = entries
    return vertex, quadric


def _crossing_samples(frame_vertices, faces, crossings, check=None):
    """Yields (cells (N, 3) int, points (N, 3), normals (N, 3)): every edge crossing once for
    each of the 4 cells around its edge, in chunks of ``SAMPLE_CHUNK`` crossings (``check()``
    before each). Points are exact surface points (the jittered ray's, ``ray_jitter`` put back);
    the edge is the one the inside points' parity puts the crossing on."""
    jitter = ray_jitter()
    for crossing in crossings:
        axis = crossing.axis
        b, c = OTHER_AXES[axis]
        for lo in range(0, len(crossing.depth), SAMPLE_CHUNK):
            if check is not None:
                check()
            part = slice(lo, lo + SAMPLE_CHUNK)
            edge = np.empty((len(crossing.depth[part]), 3), dtype=np.int64)
            edge[:, axis] = np.floor(crossing.depth[part])
            edge[:, b], edge[:, c] = crossing.column_b[part], crossing.column_c[part]
            points = edge.astype(np.float64)
            points[:, axis] = crossing.depth[part]
            points += jitter
            triangles = frame_vertices[faces[crossing.triangle[part]]]
            normals = triangle_cross(triangles)
            normals /= np.linalg.norm(normals, axis=1, keepdims=True)
            for step_b in (0, 1):
                for step_c in (0, 1):
                    cells = edge.copy()
                    cells[:, b] -= step_b
                    cells[:, c] -= step_c
                    yield cells, points, normals


def _add_to_cells(sums, surface, surface_flat, cells, points, normals) -> None:
    """Add each sample's terms (``CELL_SUMS``, times ``SUM_SCALE``, rounded) to the sums of its
    cell; samples of cells that are not surface cells (or outside the lattice) are dropped."""
    inside_box = np.all((cells >= 0) & (cells < np.array(surface.shape)), axis=1)
    cells, points, normals = cells[inside_box], points[inside_box], normals[inside_box]
    flat = np.ravel_multi_index(cells.T, surface.shape)
    on_surface = surface.reshape(-1)[flat]
    local = points[on_surface] - cells[on_surface]
    normals = normals[on_surface]
    slot = np.searchsorted(surface_flat, flat[on_surface])
    along = np.einsum("sd,sd->s", normals, local)  # n . p
    terms = [None, *local.T, *(normals[:, r] * normals[:, c] for r, c in QUADRIC_ENTRIES),
             *(normals * along[:, None]).T]
    for k, term in enumerate(terms):
        weights = None if term is None else np.round(term * SUM_SCALE)
        added = np.bincount(slot, weights, minlength=len(surface_flat))
        sums[:, k] += added * SUM_SCALE if term is None else added


def _solve_qef(sums) -> np.ndarray:
    """(n, 3) QEF minimiser of each cell as an offset from its min corner, inside the cell; NaN
    rows for cells without data.

    The QEF sum (n . (x - p))^2 is solved about the mass point m of the cell's data with
    truncated eigenvalues (``tol.qef_singular``: flat and crease cells stay well posed; the
    dropped directions keep x at m). A solution outside the cell is replaced by the QEF's
    minimum over the cell (``_minimum_in_cell``): on a crease whose nearest point to m lies in
    the next cell the vertex slides along the crease into its own cell, and it stays on the
    planes the data hold wherever the cell allows.

    Args:
        sums: (n, ``CELL_SUMS``) the cells' sums (``cell_vertices``).
    """
    count = sums[:, 0]
    has = count > 0
    mass = sums[:, 1:4] / np.where(has, count, 1.0)[:, None]
    ata = np.zeros((len(sums), 3, 3))
    for k, (r, c) in enumerate(QUADRIC_ENTRIES):
        ata[:, r, c] = ata[:, c, r] = sums[:, 4 + k]
    # planes relative to the mass point: sum n (n . (p - m)) = sum n (n . p) - (sum n n^T) m
    atb = sums[:, 10:13] - np.einsum("nij,nj->ni", ata, mass)
    pull = tol.qef_pull * np.trace(ata, axis1=1, axis2=2)
    eigval, eigvec = np.linalg.eigh(ata + pull[:, None, None] * np.eye(3))  # ascending
    keep = eigval > tol.qef_singular * eigval[:, 2:3]
    inverse = np.where(keep, 1.0 / np.where(keep, eigval, 1.0), 0.0)
    step = np.einsum("ndk,nk->nd", eigvec, np.einsum("ndk,nd->nk", eigvec, atb) * inverse)
    position = mass + step
    outside = has & np.any((position < -tol.cell_slack) | (position > 1 + tol.cell_slack), axis=1)
    if np.any(outside):
        # the dropped directions cost only the pull towards the mass point
        weight = np.where(keep, eigval, pull[:, None])[outside]
        hessian = np.einsum("nij,nj,nkj->nik", eigvec[outside], weight, eigvec[outside])
        position[outside] = _minimum_in_cell(hessian, position[outside])
    position[~has] = np.nan
    return position


#: the interior, faces, edges and corners of a cell, where the minimum of a quadratic over the
#: cell can lie: per axis, free (-1) or held at the cell's low (0) or high (1) side
CELL_PARTS = tuple(itertools.product((-1, 0, 1), repeat=3))


def _minimum_in_cell(hessian, target) -> np.ndarray:
    """(n, 3) the point of the unit cell [0, 1]^3 that minimises (x - t)^T H (x - t), for
    positive definite H (n, 3, 3) and targets t (n, 3).

    The minimum of a strictly convex quadratic over a box lies inside exactly one of the box's
    parts (its interior, a face, an edge or a corner), where it is the quadratic's minimum over
    that part's affine hull (space, plane, line, point); so it is the lowest of the 27 such
    minima that lie in the cell.
    """
    best_cost = np.full(len(target), np.inf)
    best = np.clip(target, 0.0, 1.0)  # replaced below: some part always holds the minimum
    for pattern in CELL_PARTS:
        held = [axis for axis in range(3) if pattern[axis] >= 0]
        free = [axis for axis in range(3) if pattern[axis] < 0]
        point = target.copy()
        point[:, held] = [pattern[axis] for axis in held]
        if free:
            # on the plane x_held = bounds: H_ff (x_f - t_f) = -H_fh (x_h - t_h)
            shift = np.einsum("nij,nj->ni", hessian[:, free][:, :, held],
                              point[:, held] - target[:, held])
            point[:, free] -= np.linalg.solve(hessian[:, free][:, :, free],
                                              shift[..., None])[..., 0]
        inside = np.all((point >= -tol.cell_slack) & (point <= 1 + tol.cell_slack), axis=1)
        delta = point - target
        cost = np.einsum("ni,nij,nj->n", delta, hessian, delta)
        better = inside & (cost < best_cost)
        best_cost[better], best[better] = cost[better], point[better]
    return best


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
