"""Before a run: the grid a voxel size gives, how long the run will take, and what a mesh lacks.

Front ends (the Blender add-on) show these before they start; they are bpy-free so they are
tested here:

* ``plan_grid``: a voxel size (world units) or a resolution -> the grid ``voxelize`` will make,
  with the core's limits (``RESOLUTION_MIN``..``RESOLUTION_MAX``, ``grid.MAX_VOXELS``);
* ``estimate_seconds``: the time of a run from its lattice size and its surface (the expected
  number of crossed lattice edges, ``mesh_crossings`` / ``grid_crossings``), from
  ``CALIBRATION`` measured on a 2-core CPU;
* ``open_edge_count``: edges with one face only (the mesh is not closed);
* ``nearest_face_values``: per-face values (material indices) carried onto a new mesh.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .errors import MeshError
from .grid import MAX_VOXELS
from .voxelize import grid_layout, triangle_chunks, triangle_cross

#: ``voxelize``'s limits on ``resolution`` (voxels along the longest side, one empty voxel of
#: margin on each side); tests/core/test_plan.py checks that voxelize agrees
RESOLUTION_MIN, RESOLUTION_MAX = 3, 1024
MARGIN = 1

#: Seconds of a run on one thread, per method: (s per million crossed lattice edges, s per
#: million lattice points, fixed s), a non-negative least-squares fit to whole
#: ``pipeline.remesh_mesh`` runs (voxelise, labels or network, contouring, filters) of generated
#: shapes 11 (CAD), 7 (organic) and 40 (smooth) at 48³, 96³ and 144³, networks in the numpy
#: runtime, on a quiet 2-core x86_64 machine: ``python benchmarks/bench_estimate.py --threads 1``
#: (it prints this table). The fits are within -15..+11 % (agndc), -13..+7 % (undc), -24..+28 %
#: (mc) and -36..+43 % (sharp, whose runs are short; refitted after its labels read the exact
#: edge crossings, load ~2) of the measured runs: the estimate says
#: "about", not "exactly". "distance" is the Chamfer distance of one output to its source (30k
#: samples), per output.
CALIBRATION = {
    "agndc": (29.5, 3.05, 0.162),
    # the distilled cascade, fitted the same way (9 runs, error -9..+26 %; the agndc row above
    # predicted the same runs within -13..+31 %)
    "agndc_fast": (12.8, 1.76, 0.156),
    "undc": (14.3, 0.807, 0.00785),
    "mc": (1.17, 0.0, 0.00207),
    "sharp": (7.96, 0.0, 0.031),
    "distance": (0.31, 0.0, 0.0807),
}
#: share of a learned run that does not get faster with more network threads (Amdahl): the same
#: runs on 2 threads took 1/1.18..1/1.39 of their 1-thread time (agndc, mean 1.29: 0.55 serial)
#: and 1/0.96..1/1.23 (undc, mean 1.16: 0.72 serial)
SERIAL_SHARE = {"agndc": 0.55, "agndc_fast": 0.55, "undc": 0.72}
#: the Blender operator asks before a run estimated longer than this (seconds)
CONFIRM_SECONDS = 10.0

#: Expected seconds of each stage of a remesh (``pipeline.expected_stages``), which spread the
#: progress bar over the stages (``progress.Stages``; the time shown before a run is
#: ``CALIBRATION``'s): (s per million source triangles, s per million crossed lattice edges, s
#: per million lattice points), a non-negative least-squares fit to the stage times of a
#: generated CAD part subdivided to 12k-3.1M triangles at 64³ and 128³ and of a brain-sized
#: 197x233x189 grid, every method, on ``FIT_THREADS`` network threads of a 2-core x86_64 machine
#: under load (load average 6.7; the shares matter here, not the seconds; the fits are within
#: 0.1-0.6 s of most stages, 1.7 s of voxelising, 4.2 s of Sharp's 2-33 s of intersections):
#: ``python benchmarks/bench_estimate.py --stages`` prints these tables. "distance" is the
#: Chamfer distance of one output to its source (30k samples).
STAGE_SECONDS = {
    "voxelise": (1.22, 0.0, 0.0),
    "exact intersections": (7.87, 0.0, 3.03),
    "intersection vertices": (0.0, 0.000111, 0.0),
    "marching cubes": (0.0, 0.704, 0.0105),
    "taubin smoothing": (0.0, 0.477, 0.0),
    "surface nets": (0.0, 0.0, 0.143),
    "flat patches": (0.0, 0.568, 0.107),
    "terraced planes": (0.0, 0.0, 0.154),
    # not in the fit: the terraced planes' row times the ratio of the two stages' times
    # measured on three validation shapes at 128³ and 192³ (0.58-0.87, 0.69 on average)
    "stepped floors": (0.0, 0.0, 0.106),
    "source bounds": (0.0, 0.191, 0.0),
    "dual contouring": (0.0, 0.356, 0.0198),
    "normal filter": (0.0, 10.8, 0.068),
    "fold check": (0.0, 0.0, 0.201),
    "low poly": (0.0, 169.0, 0.0),
    "distance": (0.567, 0.675, 0.0),
}
#: the network ("predict") of each learned method, in the same form, on ``FIT_THREADS``
#: threads (``SERIAL_SHARE`` scales it to other thread counts)
NETWORK_SECONDS = {
    "agndc": (0.0, 123.0, 0.461),
    "agndc_fast": (0.0, 59.5, 0.585),
    "undc": (0.0, 25.8, 0.16),
}
FIT_THREADS = 2


@dataclass(frozen=True)
class GridPlan:
    """The grid ``voxelize(vertices, faces, resolution)`` makes for a mesh of a given extent."""

    resolution: int  # voxels along the longest side, margins included (voxelize's argument)
    shape: tuple  # (X, Y, Z) voxels
    voxel_size: float  # edge of a voxel, in the units of the extent

    @property
    def voxels(self) -> int:
        return math.prod(self.shape)


def plan_grid(extent, *, voxel_size: float | None = None, resolution: int | None = None,
              source: str = "mesh") -> GridPlan:
    """The grid for a mesh whose bounding box has size ``extent`` (3,), from one of
    ``voxel_size`` (the largest voxel edge wanted, same units as ``extent``) or ``resolution``.

    Raises:
        MeshError: zero extent, a voxel size <= 0, or a grid outside the core's limits (the
            message says which voxel size or resolution would work).
    """
    extent = np.asarray(extent, dtype=np.float64).reshape(3)
    longest = float(extent.max())
    if not np.all(np.isfinite(extent)) or longest <= 0:
        raise MeshError(f"{source}: the mesh has zero size or invalid coordinates")
    if (voxel_size is None) == (resolution is None):
        raise ValueError("give exactly one of voxel_size and resolution")
    if voxel_size is not None:
        if not voxel_size > 0:
            raise MeshError(f"{source}: the voxel size must be positive, got {voxel_size}")
        # relative slack: float32 coordinates (Blender's) put 2.0000002 / (2 / 700) a hair
        # above 700
        resolution = max(math.ceil(longest / voxel_size * (1 - 1e-6)), 1) + 2 * MARGIN
        if resolution > RESOLUTION_MAX:
            # the finest size within both limits (per side and in total), so the advice works
            finest = _finest_voxel(extent)
            raise MeshError(f"{source}: a voxel size of {voxel_size:.4g} gives {resolution:,} "
                            f"voxels along its longest side ({longest:.4g}), more than "
                            f"{RESOLUTION_MAX}; use a voxel size of at least {_up(finest)}")
    elif not RESOLUTION_MIN <= int(resolution) <= RESOLUTION_MAX:
        raise MeshError(f"{source}: resolution must be in [{RESOLUTION_MIN}, {RESOLUTION_MAX}], "
                        f"got {resolution}")
    plan = _plan(extent, int(resolution))
    if plan.voxels > MAX_VOXELS:
        finest = _finest_voxel(extent)
        raise MeshError(f"{source}: a {'×'.join(map(str, plan.shape))} grid has "
                        f"{plan.voxels:,} voxels, more than the {MAX_VOXELS:,} the remesher "
                        f"handles; use a voxel size of at least {_up(finest)}")
    return plan


def _plan(extent: np.ndarray, resolution: int) -> GridPlan:
    """The grid ``voxelize`` makes at ``resolution`` (its own arithmetic, ``grid_layout``)."""
    voxel, counts = grid_layout(extent, resolution, MARGIN)
    return GridPlan(resolution, tuple(int(n) for n in counts), voxel)


def _finest_voxel(extent: np.ndarray) -> float:
    """The smallest voxel size whose grid stays within MAX_VOXELS (bisection on resolution)."""
    lo, hi = RESOLUTION_MIN, RESOLUTION_MAX
    while lo < hi:  # at most 10 steps
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if _plan(extent, mid).voxels <= MAX_VOXELS else (lo, mid - 1)
    return _plan(extent, lo).voxel_size


def _up(value: float) -> str:
    """``value`` rounded up to 3 significant digits, as text."""
    digits = 2 - math.floor(math.log10(value))
    return f"{math.ceil(value * 10 ** digits) / 10 ** digits:.{max(digits, 0)}f}"


def mesh_crossings(vertices, faces, voxel_size: float, check=None) -> float:
    """Expected number of lattice edges a mesh crosses at ``voxel_size``: the area it shows to
    each axis (sum of |normal component| x area) over the area of a voxel face.

    Args:
        vertices: (V, 3) float, in the frame the grid is built in; faces: (F, 3) int.
        check: called before each chunk of ``TRIANGLE_CHUNK`` triangles (a dense mesh's pass
            took 0.3-1.1 s before a run's first stage).
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    # (F, 3): twice the area times the unit normal
    cross = np.empty((len(faces), 3))
    for lo, triangles in triangle_chunks(vertices, faces, check):
        cross[lo:lo + len(triangles)] = triangle_cross(triangles)
    return area_crossings(cross / 2.0, voxel_size)


def area_crossings(area_vectors, voxel_size: float) -> float:
    """``mesh_crossings`` from (F, 3) area vectors (unit normal x area) of the faces."""
    return float(np.abs(np.asarray(area_vectors, dtype=np.float64)).sum()) / voxel_size ** 2


def grid_crossings(occupancy: np.ndarray) -> int:
    """Number of lattice edges a grid's surface crosses (neighbouring voxels that differ, with
    the empty padding around the grid)."""
    padded = np.pad(np.asarray(occupancy, dtype=bool), 1)
    return int(sum(np.count_nonzero(np.diff(padded, axis=axis)) for axis in range(3)))


def estimate_seconds(method: str, shape, crossings: float, *, distances: int = 0,
                     threads: int = 1) -> float:
    """Estimated seconds of one remesh (``CALIBRATION``), plus ``distances`` Chamfer distances.

    Args:
        method: a key of ``CALIBRATION``; shape: (3,) voxels of the grid; crossings: crossed
            lattice edges (``mesh_crossings`` or ``grid_crossings``); threads: the network's
            threads (``SERIAL_SHARE`` of a learned run does not speed up).
    """
    points = math.prod(int(n) + 2 for n in shape)  # the padded lattice
    total = _seconds(CALIBRATION[method], crossings, points) * thread_factor(method, threads)
    return total + distances * _seconds(CALIBRATION["distance"], crossings, 0)


def thread_factor(method: str, threads: int) -> float:
    """A method's time on ``threads`` network threads over its time on one (Amdahl, with
    ``SERIAL_SHARE``; 1 for the methods without a network)."""
    serial = SERIAL_SHARE.get(method, 1.0)
    return serial + (1.0 - serial) / max(1, int(threads))


def stage_seconds(stage: str, *, method: str = "", triangles: float = 0, crossings: float = 0,
                  points: float = 0, threads: int = FIT_THREADS) -> float:
    """Expected seconds of one stage of a remesh (``STAGE_SECONDS``; the network's, stage
    "predict", from ``NETWORK_SECONDS`` for ``method`` on ``threads`` threads); 0 for a stage
    that takes no measurable time.

    Args:
        triangles: of the source mesh (0 for a grid); crossings: crossed lattice edges
            (``grid_crossings`` or ``mesh_crossings``); points: lattice points.
    """
    if stage == "predict":
        row = NETWORK_SECONDS.get(method)
        if row is None:
            return 0.0
        scale = thread_factor(method, threads) / thread_factor(method, FIT_THREADS)
        return scale * _stage_row(row, triangles, crossings, points)
    row = STAGE_SECONDS.get(stage)
    return 0.0 if row is None else _stage_row(row, triangles, crossings, points)


def _stage_row(row, triangles, crossings, points) -> float:
    per_triangle, per_crossing, per_point = row
    return (per_triangle * triangles + per_crossing * crossings + per_point * points) / 1e6


def _seconds(row, crossings: float, points: float) -> float:
    per_crossing, per_point, fixed = row
    return (per_crossing * crossings + per_point * points) / 1e6 + fixed


def open_edge_count(vertices, faces) -> int:
    """Edges used by exactly one face, after welding vertices at identical positions (so a mesh
    split along UV seams or an unwelded STL is not counted as open). 0 for a closed mesh."""
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        return 0
    _, weld = np.unique(vertices, axis=0, return_inverse=True)
    welded = weld.reshape(-1)[faces]  # (F, 3)
    edges = np.sort(welded[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)  # (3F, 2)
    edges = edges[edges[:, 0] != edges[:, 1]]  # collapsed by the weld
    keys = edges[:, 0] * (int(welded.max()) + 1) + edges[:, 1]
    _, counts = np.unique(keys, return_counts=True)
    return int(np.count_nonzero(counts == 1))


def is_planar(vertices, rtol: float = 1e-6) -> bool:
    """All points in one plane (up to ``rtol`` of their spread): an open mesh like this (a
    plane, a single triangle) encloses nothing, whatever a voxeliser makes of it."""
    points = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    if len(points) < 4:
        return True
    # (3,) spreads along the principal axes
    spread = np.linalg.svd(points - points.mean(axis=0), compute_uv=False)
    return bool(spread[-1] <= rtol * spread[0])


def nearest_face_values(vertices, faces, values, points, *, samples: int = 200_000,
                        seed: int = 0) -> np.ndarray:
    """The value of the source face nearest to each point, e.g. material indices for the
    centroids of a remeshed surface.

    Nearest is approximated by the nearest of the face centroids and ``samples`` area-weighted
    surface samples (each tagged with its face); exact for points on the source's flat regions.

    Args:
        vertices: (V, 3) float; faces: (F, 3) int; values: (F,) per-face values;
        points: (P, 3) float queries.

    Returns:
        (P,) values, dtype of ``values``.
    """
    values = np.asarray(values)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if len(values) == 0 or np.all(values == values[0]):
        return np.full(len(points), values[0] if len(values) else 0, dtype=values.dtype)
    from scipy.spatial import cKDTree

    triangles = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    area = np.linalg.norm(triangle_cross(triangles), axis=1)  # (F,) 2x area
    rng = np.random.default_rng(seed)
    owner = np.arange(len(triangles))
    if area.sum() > 0 and samples > 0:
        owner = np.concatenate([owner, rng.choice(len(triangles), samples, p=area / area.sum())])
    uv = rng.random((len(owner), 2))  # folded onto the triangle: uniform barycentrics
    uv[: len(triangles)] = 1.0 / 3.0  # the centroids first
    fold = uv.sum(axis=1) > 1
    uv[fold] = 1 - uv[fold]
    t = triangles[owner]  # (S, 3, 3)
    sample = t[:, 0] + uv[:, :1] * (t[:, 1] - t[:, 0]) + uv[:, 1:] * (t[:, 2] - t[:, 0])
    _, nearest = cKDTree(sample).query(points)
    return values[owner[nearest]]


#: gap between side-by-side results, as a fraction of the result's width along the direction
SIDE_GAP = 0.25


def free_offset(lo, hi, direction, occupied_lo, occupied_hi, *, start: int = 1,
                tries: int = 1000) -> np.ndarray:
    """Where to put a box beside others: the first of the offsets k x step x ``direction``
    (k = start, start + 1, ...) at which the box [lo, hi] overlaps none of the occupied boxes.

    ``step`` is the box's width along ``direction`` plus ``SIDE_GAP`` of it, so results line up
    one after another. Boxes that only touch do not overlap.

    Args:
        lo, hi: (3,) the box at offset 0; direction: (3,) any length (normalised here);
        occupied_lo, occupied_hi: (N, 3) boxes to avoid.

    Returns:
        (3,) the offset to add (the one for k = start + tries - 1 if every offset overlaps).
    """
    lo, hi = np.asarray(lo, dtype=np.float64), np.asarray(hi, dtype=np.float64)
    direction = np.asarray(direction, dtype=np.float64)
    direction = direction / max(float(np.linalg.norm(direction)), 1e-300)
    width = float(np.abs(direction) @ (hi - lo))
    step = direction * (width * (1 + SIDE_GAP) if width > 0 else 1.0)
    shifts = (start + np.arange(tries))[:, None] * step  # (K, 3)
    occupied_lo = np.asarray(occupied_lo, dtype=np.float64).reshape(-1, 3)
    occupied_hi = np.asarray(occupied_hi, dtype=np.float64).reshape(-1, 3)
    # (K, N): the shifted box overlaps occupied box n on all three axes
    tol = 1e-9 * max(width, 1.0)
    overlap = np.all((lo + shifts)[:, None] < occupied_hi[None] - tol, axis=2) & \
        np.all((hi + shifts)[:, None] > occupied_lo[None] + tol, axis=2)
    free = ~overlap.any(axis=1)
    k = int(np.argmax(free)) if free.any() else tries - 1
    return shifts[k]
