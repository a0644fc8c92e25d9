"""Low poly: decimation of a remeshed mesh that merges flat regions and keeps creases.

    (V, 3), (F, 3) closed mesh --manifold3d simplify(tolerance)--> (V', 3), (F', 3), V' subset of V

``manifold3d``'s ``Manifold.simplify`` collapses edges whose collapse moves the surface by less
than a tolerance; a collapse across a crease moves it by the crease's height, so creases and
corners stay while flat regions merge into a few large triangles (a remeshed box becomes 12).
Its output is an oriented closed 2-manifold by construction, and its vertices are a subset of
the input's.

The tolerance bounds each collapse, not their sum, so the surface can drift further than the
tolerance (measured on fandisk's 128³ surface-nets mesh: 2.6x at 0.5 voxels). ``max_error`` is
therefore checked against the measured deviation (``surface_deviation``: sample points of each
surface to the other, both ways) and the tolerance searched for the largest that keeps it.
``target_faces`` is met by bisecting the tolerance (each simplify is one vectorised C++ call,
~0.1 s for 80k faces).

Every result is checked (``meshcheck``: closed, 2-manifold, consistently wound, same orientation
as the input); one that is not is replaced by the input mesh, with a logged warning.
"""

from __future__ import annotations

import logging

import numpy as np
from scipy.spatial import cKDTree

from .errors import AGNDCError
from .meshcheck import topology_violations

logger = logging.getLogger(__name__)

#: smallest face count a closed triangle mesh can have (a tetrahedron)
MIN_FACES = 4
#: simplify calls (each with a deviation measure) of the search for ``max_error``'s tolerance
ERROR_ATTEMPTS = 6
#: the search for ``max_error``'s tolerance stops when the tolerances that fit and fail are
#: this close (ratio)
ERROR_STEP = 1.3
#: the face-count search starts at 2^-TARGET_STEPS of its largest tolerance (one voxel in
#: ``pipeline.remesh``)
TARGET_STEPS = 16
#: nearest surface samples whose triangles are candidates for a point's closest triangle
CANDIDATES = 8
#: random samples of the coarser surface per face of the finer one (a remesh has two faces
#: per voxel face: about one sample per voxel face)
SAMPLES_PER_FACE = 0.5
#: seed of the surface samples: the same mesh and options give the same result
SEED = 0


def decimate(vertices, faces, *, max_error: float | None = None,
             target_faces: int | None = None,
             max_tolerance: float | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Fewer, larger triangles on flat regions; creases, corners and the topology kept.

    Args:
        vertices: (V, 3) float coordinates of a closed, outward-wound 2-manifold mesh.
        faces: (F, 3) int triangles.
        max_error: largest distance (in the vertices' units) the surface may move: measured
            from sample points of each surface to the other (``surface_deviation``).
        target_faces: stop at about this many faces (at most this many, unless the mesh cannot
            be simplified that far, or ``max_error`` is reached first).
        max_tolerance: the largest simplify tolerance the search for ``target_faces`` may use
            (default: the mesh's diagonal). Beyond about a voxel the face count rises again
            and then falls only as features vanish, so ``pipeline.remesh`` passes one voxel.

    Returns:
        vertices (V', 3) float64 and faces (F', 3) int64; the input itself when neither option
        is set or the result fails the closed-2-manifold check (then with a logged warning).
    """
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    check_options(max_error, target_faces)
    if (max_error is None and target_faces is None) or len(faces) == 0:
        return vertices, faces
    manifold = _to_manifold(vertices, faces)
    if manifold is None:
        logger.warning("low poly skipped: the mesh is not a closed 2-manifold for manifold3d")
        return vertices, faces
    tolerance = np.inf
    if max_error is not None:
        tolerance = _tolerance_within(manifold, vertices, faces, float(max_error))
    if target_faces is not None:
        upper = tolerance if max_tolerance is None else min(tolerance, max_tolerance)
        tolerance = _tolerance_for_faces(manifold, vertices, int(target_faces), upper)
    if tolerance <= 0:
        return vertices, faces
    out_vertices, out_faces = _simplified(manifold, tolerance)
    return _checked(out_vertices, out_faces, vertices, faces)


def check_options(max_error, target_faces) -> None:
    """Raise AGNDCError for a bound or a face count no decimation can use."""
    if max_error is not None and not (np.isfinite(max_error) and max_error > 0):
        raise AGNDCError(f"low poly: the error bound must be a positive number, got {max_error}")
    if target_faces is not None and int(target_faces) < MIN_FACES:
        raise AGNDCError(f"low poly: the target face count must be at least {MIN_FACES} (a "
                         f"closed mesh), got {target_faces}")


def _to_manifold(vertices_vx3: np.ndarray, faces_fx3: np.ndarray):
    """A ``manifold3d.Manifold`` of the mesh (float64 positions, the same vertex indices), or
    None when manifold3d does not accept it as an oriented 2-manifold."""
    import manifold3d

    mesh = manifold3d.Mesh64(vert_properties=np.ascontiguousarray(vertices_vx3),
                             tri_verts=np.ascontiguousarray(faces_fx3, dtype=np.uint64))
    manifold = manifold3d.Manifold(mesh)
    if manifold.status() != manifold3d.Error.NoError or manifold.is_empty():
        return None
    return manifold


def _simplified(manifold, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """(V', 3) float64, (F', 3) int64 of ``manifold.simplify(tolerance)``."""
    mesh = manifold.simplify(float(tolerance)).to_mesh64()
    vertices = np.asarray(mesh.vert_properties, dtype=np.float64)[:, :3]
    return np.ascontiguousarray(vertices), np.asarray(mesh.tri_verts, dtype=np.int64)


def _tolerance_within(manifold, vertices, faces, max_error: float) -> float:
    """The largest tolerance found (``max_error`` first, then a log-scale search below it)
    whose result deviates from the input by at most ``max_error`` (``surface_deviation``);
    0 when none does (the input is returned then)."""
    good, bad, tolerance = 0.0, None, max_error
    for _ in range(ERROR_ATTEMPTS):
        out_vertices, out_faces = _simplified(manifold, tolerance)
        fits = len(out_faces) == len(faces) or surface_deviation(  # nothing collapsed: fits
            vertices, faces, out_vertices, out_faces, bound=max_error) <= max_error
        if fits and bad is None:
            return tolerance
        good, bad = (tolerance, bad) if fits else (good, tolerance)
        if good and bad / good < ERROR_STEP:
            break
        # the deviation grows faster than the tolerance (2.6x at 0.5 voxels): start a quarter
        # down, then bisect between the largest tolerance that fits and the smallest that fails
        tolerance = np.sqrt(good * bad) if good else tolerance / 4
    return good


def _tolerance_for_faces(manifold, vertices, target: int, upper: float) -> float:
    """The smallest tolerance, up to ``upper``, whose result has at most ``target`` faces.

    The face count falls with the tolerance only up to about a voxel: larger tolerances let
    early collapses block later ones and leave more faces (measured on a 128³ CAD part: 1,526
    faces at 1 voxel, 7,702 at 16). So the tolerance doubles from a tiny one up to ``upper``
    until the count first reaches the target, then is bisected between the last two; when no
    tolerance reaches it, the one with the fewest faces is returned.
    """
    extent = float(np.linalg.norm(np.ptp(vertices, axis=0)))
    upper = min(upper, extent)
    tolerances = upper * 2.0 ** -np.arange(TARGET_STEPS, -1, -1.0)  # rising, ends at upper
    previous, fewest = 0.0, (manifold.num_tri(), 0.0)
    for tolerance in tolerances:
        count = manifold.simplify(tolerance).num_tri()
        if count <= target:
            return _bisect_tolerance(manifold, target, previous, tolerance)
        fewest = min(fewest, (count, tolerance))
        previous = tolerance
    return fewest[1]


def _bisect_tolerance(manifold, target: int, lo: float, hi: float) -> float:
    """Narrow [lo, hi] (more than ``target`` faces at lo, at most at hi) to 2 %; returns hi."""
    while lo > 0 and hi / lo > 1.02:
        mid = np.sqrt(lo * hi)
        if manifold.simplify(mid).num_tri() > target:
            lo = mid
        else:
            hi = mid
    return hi


def _checked(out_vertices, out_faces, vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """The decimated mesh if it is a closed, consistently wound 2-manifold with the input's
    orientation (the signed volume keeps its sign); otherwise the input, with a warning."""
    problems = {k: v for k, v in topology_violations(out_vertices, out_faces).items() if v}
    if np.sign(signed_volume(out_vertices, out_faces)) != np.sign(signed_volume(vertices, faces)):
        problems["orientation_flipped"] = 1
    if problems or len(out_faces) < MIN_FACES:
        logger.warning("low poly skipped: the decimated mesh is not a closed outward 2-manifold "
                       "(%s); the full mesh is kept", problems or "too few faces")
        return vertices, faces
    return out_vertices, out_faces


def signed_volume(vertices_vx3: np.ndarray, faces_fx3: np.ndarray) -> float:
    """Signed volume of a closed mesh (positive when wound outward)."""
    a, b, c = (vertices_vx3[faces_fx3[:, k]] for k in range(3))
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def surface_deviation(vertices_a, faces_a, vertices_b, faces_b, *,
                      bound: float | None = None) -> float:
    """Largest distance between two nearby surfaces, measured at sample points both ways.

    The points measured on the finer surface are its vertices (a remesh's are ~1 voxel
    apart); on the coarser one its vertices, face centroids and area-weighted random samples
    (``SAMPLES_PER_FACE`` per face of the finer mesh), since its large triangles need points
    inside. Each point is compared with the exact closest point of the other surface among the
    triangles of its ``CANDIDATES`` nearest sample points there (the finer surface: its face
    centroids), which can only overestimate a distance. Points found further than ``bound``
    are measured again against the whole surface, largest first, until one is confirmed, so
    the answer is exact about ``<= bound``; without a bound it is an upper bound.

    Args:
        vertices_a, vertices_b: (Va, 3), (Vb, 3) float64; faces_a, faces_b: (Fa, 3), (Fb, 3).
    """
    if len(faces_a) < len(faces_b):
        vertices_a, faces_a, vertices_b, faces_b = vertices_b, faces_b, vertices_a, faces_a
    count = int(SAMPLES_PER_FACE * len(faces_a))
    coarse, coarse_owner = _surface_points(vertices_b, faces_b, count,
                                           np.random.default_rng(SEED))
    centroids = vertices_a[faces_a].mean(axis=1)  # (Fa, 3)
    fine_owner = np.arange(len(faces_a))
    worst = 0.0
    for points, samples, owner, vertices, faces in (
            (vertices_a, coarse, coarse_owner, vertices_b, faces_b),
            (coarse, centroids, fine_owner, vertices_a, faces_a)):
        gap = _candidate_distances(points, samples, owner, vertices, faces)
        worst = max(worst, _confirmed_max(gap, points, vertices, faces, bound))
    return worst


def _surface_points(vertices_vx3, faces_fx3, count: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """(P, 3) points on a mesh and (P,) the face each lies on: its vertices, its face centroids
    and ``count`` area-weighted random samples."""
    n_faces = len(faces_fx3)
    vertex_face = np.zeros(len(vertices_vx3), dtype=np.int64)
    vertex_face[faces_fx3.reshape(-1)] = np.repeat(np.arange(n_faces), 3)  # one face of each
    triangles = vertices_vx3[faces_fx3]  # (F, 3, 3)
    area = np.linalg.norm(np.cross(triangles[:, 1] - triangles[:, 0],
                                   triangles[:, 2] - triangles[:, 0]), axis=1)
    picked = rng.choice(n_faces, size=count, p=area / area.sum())
    uv = rng.random((count, 2))
    flip = uv.sum(axis=1) > 1
    uv[flip] = 1 - uv[flip]  # fold the unit square onto the triangle
    random = np.einsum("pk,pkd->pd", np.column_stack([1 - uv.sum(axis=1), uv]),
                       triangles[picked])
    points = np.concatenate([vertices_vx3, triangles.mean(axis=1), random])
    owner = np.concatenate([vertex_face, np.arange(n_faces), picked])
    return points, owner


def _candidate_distances(points_px3, samples_sx3, owner_s, vertices_vx3, faces_fx3,
                         chunk: int = 200_000) -> np.ndarray:
    """(P,) distance of each point to the nearest of the candidate triangles: those owning its
    ``CANDIDATES`` nearest ``samples`` (an upper bound of the distance to the surface)."""
    from trimesh.triangles import closest_point

    k = min(CANDIDATES, len(samples_sx3))
    _, nearest = cKDTree(samples_sx3).query(points_px3, k=k)
    nearest = nearest.reshape(len(points_px3), k)  # (P, k)
    out = np.zeros(len(points_px3))
    rows_per_chunk = max(1, chunk // k)
    for start in range(0, len(points_px3), rows_per_chunk):  # bounded memory, not per point
        rows = slice(start, start + rows_per_chunk)
        candidate = owner_s[nearest[rows]]  # (p, k) faces
        point = np.repeat(points_px3[rows], k, axis=0)
        closest = closest_point(vertices_vx3[faces_fx3[candidate.reshape(-1)]], point)
        out[rows] = np.linalg.norm(closest - point, axis=1).reshape(-1, k).min(axis=1)
    return out


def _confirmed_max(gap_p, points_px3, vertices_vx3, faces_fx3, bound, batch: int = 256) -> float:
    """The largest of the candidate distances ``gap_p`` once those above ``bound`` are measured
    exactly (trimesh's closest point on the whole mesh), largest first, a batch at a time,
    stopping at the first batch that confirms a distance above ``bound``. Without a bound, the
    candidate distances' maximum (an upper bound)."""
    import trimesh

    if bound is None:
        return float(gap_p.max(initial=0.0))
    suspect = np.flatnonzero(gap_p > bound)
    suspect = suspect[np.argsort(-gap_p[suspect])]
    gap_p = gap_p.copy()
    mesh = trimesh.Trimesh(vertices_vx3, faces_fx3, process=False) if len(suspect) else None
    for start in range(0, len(suspect), batch):
        rows = suspect[start:start + batch]
        _, exact, _ = trimesh.proximity.closest_point(mesh, points_px3[rows])
        gap_p[rows] = np.minimum(gap_p[rows], exact)
        if gap_p[rows].max() > bound:
            return float(gap_p[rows].max())  # confirmed: over the bound
    return float(gap_p.max(initial=0.0))
