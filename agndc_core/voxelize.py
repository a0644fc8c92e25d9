"""Mesh -> binary voxel grid, by ray casting along the three lattice axes.

A point is inside when the rays through it say so. Each axis casts one ray per lattice column
(all at once, vectorised over triangles x columns), accumulates the crossings below every point
with one ``bincount`` and a running sum, and gives a per-axis verdict; the three verdicts vote.

* Closed, consistently oriented meshes use the non-zero winding rule, which is exact and also
  right for overlapping shells (3-D prints often are unions of intersecting parts).
* Other meshes (holes, flipped faces) use crossing parity; a hole only misleads the rays that pass
  through it, and the 2-of-3 vote outvotes them.

Query points sit at integer coordinates of the frame the triangles are given in (see grid.py for
where that frame puts voxel centres). Rays are moved off the lattice lines by a tiny irrational
jitter (``tol.ray_jitter``) so they never graze vertices or edges of axis-aligned CAD parts.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import MeshError
from .grid import OTHER_AXES, VoxelGrid
from .tolerances import tol

#: Point-in-mesh rules, chosen per mesh by ``_choose_rule`` unless forced.
RULES = ("auto", "winding", "parity")


def voxelize(vertices, faces, resolution: int = 64, *, margin: int = 1, rule: str = "auto",
             shift=(0.0, 0.0, 0.0), source: str = "mesh", check=None) -> VoxelGrid:
    """Voxelise a triangle mesh into a binary grid.

    Args:
        vertices: (V, 3) float, world coordinates.
        faces: (F, 3) int, triangle vertex indices.
        resolution: number of voxels along the longest side of the mesh bounding box.
        margin: empty voxels kept around the shape on every side (counted inside ``resolution``
            on the longest axis), so the outer surface is always closed.
        rule: "auto", "winding" or "parity" (see module docstring).
        shift: (3,) sub-voxel offset of the grid, in voxels (training augmentation: the same shape
            seen at different positions relative to the voxel centres).
        check: called between chunks of the work (``inside_points``): a cancelled run stops
            within a fraction of a second even on a million triangles.

    Returns:
        VoxelGrid whose voxel centres are the sample points; voxel size is the same on all axes;
        its ``source_bounds`` is the mesh's bounding box.
    """
    vertices, faces, used = checked_surface(vertices, faces, source)
    if check is not None:
        check()
    if not 2 * margin + 1 <= resolution <= 1024:
        raise MeshError(f"{source}: resolution must be in [{2 * margin + 1}, 1024], "
                        f"got {resolution}")
    # the surface's own extent (a stray vertex must not shrink the shape in its grid)
    lo, hi = used.min(axis=0), used.max(axis=0)
    voxel, counts = grid_layout(hi - lo, resolution, margin)
    # centre the grid on the bounding box; voxel i's centre is at origin + i * voxel
    origin = (lo + hi) / 2 - (counts - 1) * voxel / 2 + np.asarray(shift, dtype=np.float64) * voxel
    points_frame = (vertices - origin) / voxel
    # checks between the mesh checks, the winding-rule test and the ray casting: each a pass
    # over every face of a dense mesh
    rule = _choose_rule(faces, rule, check)
    occupancy = inside_points(points_frame, faces, tuple(counts), rule=rule, check=check)
    return VoxelGrid.from_spacing(occupancy, voxel, origin, source=source,
                                  source_bounds=np.stack([lo, hi]))


def grid_layout(extent, resolution: int, margin: int = 1) -> tuple[float, np.ndarray]:
    """Voxel size and (3,) int voxel counts of the grid ``voxelize`` makes for a bounding box of
    size ``extent``: the longest side spans ``resolution - 2 * margin`` voxels, every axis gets
    ``margin`` empty voxels at each end (the one place this arithmetic lives; ``plan.py`` asks
    it what a grid will be before voxelising)."""
    extent = np.asarray(extent, dtype=np.float64).reshape(3)
    voxel = float(extent.max()) / (resolution - 2 * margin)
    counts = np.maximum(np.ceil(extent / voxel - 1e-9).astype(int), 1) + 2 * margin
    counts[np.argmax(extent)] = resolution
    return voxel, counts


def check_mesh(vertices, faces, source: str = "mesh") -> tuple[np.ndarray, np.ndarray]:
    """Validate and convert a mesh: (V, 3) float64 and (F, 3) int64; MeshError names the problem."""
    vertices, faces, _ = checked_surface(vertices, faces, source)
    return vertices, faces


def checked_surface(vertices, faces, source: str = "mesh"):
    """``check_mesh``, plus the (U, 3) vertices some face uses: the surface's own points (a
    loose vertex is not part of it, so a stray or non-finite one neither sets the extent nor
    fails the check)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise MeshError(f"{source}: vertices must have shape (V, 3), got {vertices.shape}")
    if faces.size == 0:
        raise MeshError(f"{source}: the mesh has no faces, nothing to voxelise")
    if faces.ndim != 2 or faces.shape[1] != 3 or faces.dtype.kind not in "iu":
        raise MeshError(f"{source}: faces must be an (F, 3) integer array, got {faces.shape} "
                        f"{faces.dtype}")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise MeshError(f"{source}: faces index vertices outside 0..{len(vertices) - 1}")
    # the used vertices by marking, not np.unique: a sort of a dense mesh's 9M corners took
    # 0.5 s without a cancellation check
    marked = np.zeros(len(vertices), dtype=bool)
    marked[faces.reshape(-1)] = True
    used = vertices[marked]
    if not np.all(np.isfinite(used)):
        raise MeshError(f"{source}: the mesh has non-finite vertex coordinates")
    if np.ptp(used, axis=0).max() <= 0:
        raise MeshError(f"{source}: the mesh has zero extent (all vertices coincide)")
    return vertices, np.asarray(faces, dtype=np.int64), used


def inside_points(vertices_vx3: np.ndarray, faces_fx3: np.ndarray, dims: tuple[int, int, int], *,
                  rule: str = "winding", check=None) -> np.ndarray:
    """Inside/outside of the integer points of a box, by voting rays along x, y and z.

    Args:
        vertices_vx3: (V, 3) float, the mesh in the frame where the query points are the
            integer points (i, j, k), 0 <= i < dims[0] etc.; faces_fx3: (F, 3) int.
        dims: (3,) number of points per axis.
        rule: "winding" (non-zero rule) or "parity".
        check: called between chunks of the ray casting (e.g. raises ``CancelledError`` when a
            run is cancelled).

    Returns:
        (dims) bool.
    """
    if rule not in ("winding", "parity"):
        raise ValueError(f"rule must be 'winding' or 'parity', got {rule!r}")
    return inside_from_crossings(lattice_crossings(vertices_vx3, faces_fx3, dims, check), dims,
                                 rule)


def inside_from_crossings(crossings, dims, rule: str = "winding") -> np.ndarray:
    """(dims) bool: the 2-of-3 vote of the three axes' verdicts (``lattice_crossings``)."""
    votes = np.zeros(dims, dtype=np.uint8)
    for crossing in crossings:
        votes += _inside_along_axis(crossing, dims, rule)
    return votes >= 2


def ray_jitter() -> np.ndarray:
    """(3,) offset of every query point from its lattice point, in grid units: each axis's
    rays run this far off the lattice lines on the two other axes (``tol.ray_jitter``)."""
    return np.array([tol.ray_jitter[0], tol.ray_jitter[1],
                     0.5 * (tol.ray_jitter[0] + tol.ray_jitter[1])])


@dataclass
class Crossings:
    """Where the rays of one axis cross the mesh: the ray of lattice column (b, c) (``b, c =
    OTHER_AXES[axis]``, jittered by ``ray_jitter``) crosses ``triangle`` at coordinate ``depth``
    along ``axis``, in the jittered frame: the crossing lies between lattice points
    ``floor(depth)`` and ``floor(depth) + 1`` of the column. All arrays (H,)."""

    axis: int
    column_b: np.ndarray  # int64
    column_c: np.ndarray  # int64
    depth: np.ndarray  # float64
    facing: np.ndarray  # int8: +1 where the triangle faces +axis, -1 where it faces -axis
    triangle: np.ndarray  # int64 face index


#: triangles per chunk of the ray set-up (a gather and a few min/max over each): bounds the time
#: between two cancellation checks on a dense mesh (~0.1 s on one core)
TRIANGLE_CHUNK = 1 << 18


def triangle_chunks(vertices, faces, check=None):
    """Yields (first face index, (n, 3, 3) triangles) of consecutive chunks of
    ``TRIANGLE_CHUNK`` faces, ``check()`` before each: every per-triangle pass over a dense
    mesh (ray set-up, areas, crossings, samples) goes through this, so Esc is honoured inside."""
    for lo in range(0, len(faces), TRIANGLE_CHUNK):
        if check is not None:
            check()
        yield lo, vertices[faces[lo:lo + TRIANGLE_CHUNK]]


def triangle_cross(triangles: np.ndarray) -> np.ndarray:
    """(F, 3) cross product of each triangle's two edges from its first corner: the normal
    times twice the area."""
    return np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])


def lattice_crossings(vertices_vx3, faces_fx3, dims, check=None) -> list[Crossings]:
    """Every crossing of the mesh by the rays of the lattice columns along x, y and z.

    The mesh is moved by ``-ray_jitter()``, which is moving every query point by
    ``+ray_jitter()``, for all three axes alike. ``check()`` runs before each chunk of
    ``TRIANGLE_CHUNK`` triangles of the column ranges and before each chunk of the rays'
    (triangle, column) pairs; the chunks give the same crossings whatever their size.
    """
    jittered = np.asarray(vertices_vx3, dtype=np.float64) - ray_jitter()
    faces = np.asarray(faces_fx3, dtype=np.int64)
    low, high = _column_ranges(jittered, faces, dims, check)
    return [_column_hits(jittered, faces, low, high, dims, axis, check) for axis in range(3)]


def _column_ranges(vertices, faces, dims, check=None):
    """(F, 3) int32 first and last lattice line that each triangle spans along each axis (empty
    where last < first), clipped to the box; in chunks of ``TRIANGLE_CHUNK`` triangles."""
    limit = np.asarray(dims)
    low = np.empty((len(faces), 3), dtype=np.int32)
    high = np.empty((len(faces), 3), dtype=np.int32)
    for lo, triangles in triangle_chunks(vertices, faces, check):
        low[lo:lo + len(triangles)] = np.clip(np.ceil(triangles.min(axis=1)), 0, limit)
        high[lo:lo + len(triangles)] = np.clip(np.floor(triangles.max(axis=1)), -1, limit - 1)
    return low, high


#: directed edges per group of the winding-rule test (two sorts each): bounds the time between
#: two cancellation checks on a dense mesh (~0.15 s on one core)
EDGE_CHUNK = 1 << 21


def _choose_rule(faces: np.ndarray, rule: str, check=None) -> str:
    """Winding for closed consistently-oriented meshes (every directed edge exactly once, and its
    twin too), else parity (``check()`` between its passes)."""
    if rule not in RULES:
        raise MeshError(f"unknown point-in-mesh rule {rule!r}; choose one of {RULES}")
    if rule != "auto":
        return rule
    tick = check if check is not None else (lambda: None)
    tick()
    faces = np.asarray(faces, dtype=np.int64)
    # directed edges start -> end of every face (slices, not a fancy-indexed copy: 3x faster)
    start = faces.reshape(-1)
    end = np.concatenate([faces[:, 1:], faces[:, :1]], axis=1).reshape(-1)
    n = int(start.max()) + 1
    tick()
    # an edge, its repeats and its twin share their lower vertex: testing groups of lower
    # vertices one by one (about EDGE_CHUNK edges each) is testing all edges at once
    lower = np.minimum(start, end)
    for first, last in chunk_runs(np.bincount(lower, minlength=n), EDGE_CHUNK):
        tick()
        group = (lower >= first) & (lower < last)
        keys = np.sort(start[group] * n + end[group])
        if np.any(keys[1:] == keys[:-1]):
            return "parity"  # an edge used twice in the same direction: inconsistent orientation
        tick()
        if not np.array_equal(keys, np.sort(end[group] * n + start[group])):
            return "parity"  # an edge without its twin: not closed
    return "winding"


def chunk_runs(work: np.ndarray, budget: int, max_items: int | None = None) -> list:
    """Consecutive runs (start, end) of items whose ``work`` (per item, >= 0) adds up to about
    ``budget`` each, never splitting an item, and at most ``max_items`` items long."""
    ends = np.cumsum(work)
    total = int(ends[-1]) if len(ends) else 0
    cuts = np.searchsorted(ends, np.arange(budget, total, budget), side="left") + 1
    bounds = [[0], cuts, [len(work)]]
    if max_items is not None:
        bounds.append(np.arange(0, len(work), max_items))
    bounds = np.unique(np.concatenate(bounds))
    return list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))


#: (triangle, column) candidate pairs per chunk of the ray casting: bounds the temporaries
#: (~150 bytes a pair) and the time between two cancellation checks (~0.2 s on one core)
PAIR_CHUNK = 1 << 21


def _column_hits(vertices, faces, low, high, dims, axis: int, check=None) -> Crossings:
    """The crossings of the rays along ``axis`` (``lattice_crossings``): the triangles whose
    column ranges hold a column, in chunks of at most ``PAIR_CHUNK`` candidate (triangle,
    column) pairs and ``TRIANGLE_CHUNK`` triangles (``check()`` before each)."""
    b, c = OTHER_AXES[axis]
    n_b = np.maximum(high[:, b].astype(np.int64) - low[:, b] + 1, 0)
    n_c = np.maximum(high[:, c].astype(np.int64) - low[:, c] + 1, 0)
    pairs = n_b * n_c
    candidates = np.flatnonzero(pairs)  # a dense mesh's small triangles mostly hold no column
    parts = []
    for lo, hi in chunk_runs(pairs[candidates], PAIR_CHUNK, TRIANGLE_CHUNK):
        if check is not None:
            check()
        ids = candidates[lo:hi]
        col_b, col_c, depth, facing, local = _chunk_hits(
            vertices[faces[ids]], axis, low[ids, b].astype(np.int64),
            low[ids, c].astype(np.int64), n_b[ids], n_c[ids])
        parts.append((col_b, col_c, depth, facing, ids[local]))
    if not parts:
        empty = np.zeros(0, dtype=np.int64)
        return Crossings(axis, empty, empty, np.zeros(0), np.zeros(0, dtype=np.int8), empty)
    return Crossings(axis, *(np.concatenate(arrays) for arrays in zip(*parts)))


def _chunk_hits(triangles, axis, b_lo, c_lo, n_b, n_c):
    """The hits of a chunk of triangles, given their projected column boxes: column
    coordinates, depths, facings and the index of the hit triangle within the chunk."""
    b, c = OTHER_AXES[axis]
    tb, tc, ta = triangles[:, :, b], triangles[:, :, c], triangles[:, :, axis]
    per_triangle = n_b * n_c
    # enumerate the columns inside each triangle's projected bounding box
    tri = np.repeat(np.arange(len(triangles)), per_triangle)
    local = np.arange(tri.size) - np.repeat(np.cumsum(per_triangle) - per_triangle, per_triangle)
    col_b = b_lo[tri] + local // n_c[tri]
    col_c = c_lo[tri] + local % n_c[tri]
    # signed areas of the sub-triangles opposite each vertex (2-D barycentric weights)
    pb, pc = tb[tri], tc[tri]
    w = np.empty((tri.size, 3))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        w[:, i] = (pb[:, j] - col_b) * (pc[:, k] - col_c) - (pb[:, k] - col_b) * (pc[:, j] - col_c)
    hit = np.all(w > 0, axis=1) | np.all(w < 0, axis=1)
    w, tri, col_b, col_c = w[hit], tri[hit], col_b[hit], col_c[hit]
    total = w.sum(axis=1)
    depth = (w * ta[tri]).sum(axis=1) / total
    # total > 0 means counter-clockwise in (b, c), i.e. the normal points along +axis
    facing = np.where(total > 0, 1, -1).astype(np.int8)
    return col_b, col_c, depth, facing, tri


def _inside_along_axis(crossings: Crossings, dims, rule: str) -> np.ndarray:
    """(dims) uint8 verdict (0/1) of the rays cast along +axis."""
    axis = crossings.axis
    b, c = OTHER_AXES[axis]
    n_a = dims[axis]
    col_b, col_c, depth, facing = (crossings.column_b, crossings.column_c, crossings.depth,
                                   crossings.facing)
    # a crossing at depth t lies below every point with coordinate > t: index floor(t) + 1 onwards
    start = np.clip(np.floor(depth).astype(np.int64) + 1, 0, n_a)
    flat = (col_b * dims[c] + col_c) * (n_a + 1) + start
    size = dims[b] * dims[c] * (n_a + 1)
    if rule == "parity":
        toggles = (np.bincount(flat, minlength=size) & 1).astype(np.uint8)
        state = np.bitwise_xor.accumulate(toggles.reshape(dims[b], dims[c], n_a + 1), axis=2)
        inside = state[:, :, :n_a]
    else:
        # entering through a face that looks down the ray (facing -axis) adds one
        weights = -facing.astype(np.float64)
        steps = np.bincount(flat, weights=weights, minlength=size).astype(np.int32)
        winding = np.cumsum(steps.reshape(dims[b], dims[c], n_a + 1), axis=2)
        inside = (winding[:, :, :n_a] != 0).astype(np.uint8)
    # axes are (b, c, axis): move them back to (0, 1, 2)
    order = np.argsort([b, c, axis])
    return np.transpose(inside, order)
