"""Surface metrics of a predicted mesh against its ground truth, as UNDC's ``eval_100000.py``
defines them (CD, F1, NC, ECD, EF1).

Both meshes are put in the **ground truth's** normalised frame (bounding-box centre at the
origin, longest side 1, so the shape lies in [-0.5, 0.5]^3); a prediction is never normalised
by its own box, or a uniformly shrunk prediction would score perfectly. Each surface is then
sampled with ``N_SAMPLES`` area-weighted points carrying their face normals, and every metric
is computed on the two point sets with k-d trees:

* ``cd``  mean squared nearest-neighbour distance GT->pred plus pred->GT (raw, not x1e5);
* ``f1``  harmonic mean of recall (GT points within ``F1_THRESHOLD`` of pred) and precision;
* ``nc``  mean |n . n_nn| over both directions (orientation-free: UNDC's faces are unoriented);
* ``ecd`` the same as CD restricted to *edge points*, but with non-squared distances;
* ``ef1`` F1 of the edge points with ``EDGE_F1_THRESHOLD``.

An edge point is a sample with another sample of the same set within ``EDGE_RADIUS`` whose
normal differs sharply (|n . n'| < ``EDGE_DOT``). Reports multiply by ``REPORT_SCALE`` like the
paper (``format_row``).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial import cKDTree

from .errors import MeshError
from .voxelize import triangle_chunks, triangle_cross

#: points sampled on each surface; the paper's protocol (its sampling noise alone gives
#: CD ~ 0.9e-5 between two samplings of one mesh, so fewer points would blur the table)
N_SAMPLES = 100_000
#: F1 distance threshold in the normalised frame: a fifth of a 64^3 cell (0.0156)
F1_THRESHOLD = 0.003
#: neighbourhood radius in which a sharp normal change makes a sample an edge point
EDGE_RADIUS = 0.004
#: |n . n'| below this marks a crease sharper than ~78 degrees (arccos 0.2)
EDGE_DOT = 0.2
#: EF1 distance threshold; looser than F1 because edge points are sparse along the crease
EDGE_F1_THRESHOLD = 0.005
#: factors applied for reporting, as in the paper's tables (CD x 10^5, ECD x 10^2)
REPORT_SCALE = {"cd": 1e5, "ecd": 1e2}
#: faces with an area below this fraction of the mean area get zero sampling weight (their
#: cross product is numerical noise, so their normal would be arbitrary)
DEGENERATE_AREA = 1e-12
#: values reported when the prediction has no surface at all
WORST_CASE = {"cd": math.inf, "f1": 0.0, "nc": 0.0, "ecd": math.inf, "ef1": 0.0}


def normalization(gt_vertices) -> tuple[np.ndarray, float]:
    """The ground truth's frame: ``normalised = (v - center) / scale``.

    Args:
        gt_vertices: (V, 3) float, ground-truth vertex positions.

    Returns:
        center: (3,) float64, the bounding-box centre.
        scale: float, the longest bounding-box side (so the shape fits in [-0.5, 0.5]^3).

    Raises:
        MeshError: no vertices, non-finite coordinates or zero extent.
    """
    v = np.asarray(gt_vertices, dtype=np.float64).reshape(-1, 3)
    if len(v) == 0 or not np.all(np.isfinite(v)):
        raise MeshError("ground truth: vertices are empty or not finite")
    lo, hi = v.min(axis=0), v.max(axis=0)
    scale = float((hi - lo).max())
    if scale <= 0:
        raise MeshError("ground truth: zero extent, cannot define a normalised frame")
    return (lo + hi) / 2, scale


def sample_surface(vertices, faces, n: int, rng, check=None) -> tuple[np.ndarray, np.ndarray]:
    """Area-weighted uniform samples on a triangle mesh, with the sampled faces' unit normals.

    Args:
        vertices: (V, 3) float.
        faces: (F, 3) int.
        n: number of samples.
        rng: ``np.random.Generator`` (or a seed for ``np.random.default_rng``).
        check: called before each chunk of ``TRIANGLE_CHUNK`` triangles of the area pass (a
            dense mesh's pass took 0.5 s); the chunks give the same samples.

    Returns:
        points: (n, 3) float64.
        normals: (n, 3) float64, unit face normals (sign follows the winding).

    Raises:
        MeshError: the mesh has no face of positive area.
    """
    rng = np.random.default_rng(rng)
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    area2 = np.empty(len(faces))  # (F,) twice the area
    for lo, triangles in triangle_chunks(vertices, faces, check):
        area2[lo:lo + len(triangles)] = np.linalg.norm(triangle_cross(triangles), axis=1)
    total = area2.sum()
    if len(area2) == 0 or not np.isfinite(total) or total <= 0:
        raise MeshError("cannot sample a surface without any face of positive area")
    weight = np.where(area2 > DEGENERATE_AREA * total / len(area2), area2, 0.0)
    cdf = np.cumsum(weight)
    # inverse-CDF draw (zero-weight faces own an empty interval); the clip guards the float
    # edge case u * cdf[-1] == cdf[-1] and keeps it on a face of positive weight
    idx = np.searchsorted(cdf, rng.random(n) * cdf[-1], side="right")
    idx = np.minimum(idx, np.flatnonzero(weight)[-1])  # (n,)
    # uniform barycentrics: fold the unit square onto the triangle
    uv = rng.random((n, 2))
    flip = uv.sum(axis=1) > 1
    uv[flip] = 1 - uv[flip]
    t = vertices[faces[idx]]  # (n, 3, 3)
    points = t[:, 0] + uv[:, :1] * (t[:, 1] - t[:, 0]) + uv[:, 1:] * (t[:, 2] - t[:, 0])
    normals = triangle_cross(t) / area2[idx, None]
    return points, normals


def edge_points(points: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """Indices of the samples lying on a sharp crease (UNDC's edge-point rule).

    Args:
        points: (n, 3) float, samples of one surface.
        normals: (n, 3) float, their unit normals.

    Returns:
        (m,) int64, sorted indices of the samples that have another sample within
        ``EDGE_RADIUS`` whose normal satisfies |n . n'| < ``EDGE_DOT``.
    """
    pairs = cKDTree(points).query_pairs(EDGE_RADIUS, output_type="ndarray")  # (p, 2)
    dots = np.abs(np.einsum("ij,ij->i", normals[pairs[:, 0]], normals[pairs[:, 1]]))
    return np.unique(pairs[dots < EDGE_DOT])


def _f1(d_gt_to_pred: np.ndarray, d_pred_to_gt: np.ndarray, threshold: float) -> float:
    """Harmonic mean of recall (GT side) and precision (prediction side) at ``threshold``."""
    recall = float(np.mean(d_gt_to_pred < threshold))
    precision = float(np.mean(d_pred_to_gt < threshold))
    if recall + precision == 0:
        return 0.0
    return 2 * recall * precision / (recall + precision)


def _edge_metrics(gt_pts, gt_nrm, pred_pts, pred_nrm) -> dict:
    """ECD, EF1 and the edge-point counts (NaN metrics when the GT has no edge points)."""
    gt_e = gt_pts[edge_points(gt_pts, gt_nrm)]  # (m_gt, 3)
    pred_e = pred_pts[edge_points(pred_pts, pred_nrm)]  # (m_pred, 3)
    out = {"n_gt_edge_points": len(gt_e), "n_pred_edge_points": len(pred_e)}
    if len(gt_e) == 0:
        # nothing to compare: the caller skips this shape in ECD/EF1 averages
        return {"ecd": math.nan, "ef1": math.nan, **out}
    if len(pred_e) == 0:
        pred_e = np.zeros((1, 3))  # the reference's dummy set: one point at the origin
    d_gp = cKDTree(pred_e).query(gt_e)[0]
    d_pg = cKDTree(gt_e).query(pred_e)[0]
    ecd = float(d_gp.mean() + d_pg.mean())
    return {"ecd": ecd, "ef1": _f1(d_gp, d_pg, EDGE_F1_THRESHOLD), **out}


def evaluate_samples(gt_pts, gt_nrm, pred_pts, pred_nrm) -> dict:
    """All metrics from two already sampled, already normalised point sets.

    Args:
        gt_pts, gt_nrm: (n, 3) float, ground-truth samples and unit normals.
        pred_pts, pred_nrm: (m, 3) float, predicted samples and unit normals (m >= 1).

    Returns:
        dict with float ``cd``, ``f1``, ``nc``, ``ecd``, ``ef1`` and int ``n_gt_edge_points``,
        ``n_pred_edge_points`` (see the module docstring).
    """
    d_gp, i_gp = cKDTree(pred_pts).query(gt_pts)  # (n,) GT -> nearest predicted sample
    d_pg, i_pg = cKDTree(gt_pts).query(pred_pts)  # (m,) prediction -> nearest GT sample
    nc_gp = np.abs(np.einsum("ij,ij->i", gt_nrm, pred_nrm[i_gp])).mean()
    nc_pg = np.abs(np.einsum("ij,ij->i", pred_nrm, gt_nrm[i_pg])).mean()
    return {
        "cd": float(np.mean(d_gp**2) + np.mean(d_pg**2)),
        "f1": _f1(d_gp, d_pg, F1_THRESHOLD),
        "nc": float((nc_gp + nc_pg) / 2),
        **_edge_metrics(gt_pts, gt_nrm, pred_pts, pred_nrm),
    }


def _has_area(vertices: np.ndarray, faces: np.ndarray, check=None) -> bool:
    """True when the mesh has at least one face of positive, finite area (``check()`` before
    each chunk of ``TRIANGLE_CHUNK`` triangles)."""
    if len(faces) == 0 or not np.all(np.isfinite(vertices)):
        return False
    for _, triangles in triangle_chunks(vertices, faces, check):
        if np.linalg.norm(triangle_cross(triangles), axis=1).max() > 0:
            return True
    return False


def evaluate(pred_vertices, pred_faces, gt_vertices, gt_faces, *, n_samples: int = N_SAMPLES,
             seed: int = 0) -> dict:
    """Score a predicted mesh against its ground truth in the ground truth's normalised frame.

    Args:
        pred_vertices: (Vp, 3) float; pred_faces: (Fp, 3) int (may be empty).
        gt_vertices: (Vg, 3) float; gt_faces: (Fg, 3) int.
        n_samples: points sampled on each surface.
        seed: seeds both samplings (GT first, then prediction, from one generator).

    Returns:
        dict: ``cd``, ``f1``, ``nc``, ``ecd``, ``ef1`` (raw, see ``format_row`` for the paper's
        units) and ``n_gt_edge_points``, ``n_pred_edge_points``. ``ecd``/``ef1`` are NaN when
        the GT has no edge points. A prediction without surface gets ``WORST_CASE``.

    Raises:
        MeshError: the ground truth is unusable (no area, zero extent, non-finite).
    """
    gt_pts, gt_nrm, pred = _normalised_samples(pred_vertices, pred_faces, gt_vertices,
                                               gt_faces, n_samples, seed)
    if pred is None:
        n_gt_edges = len(edge_points(gt_pts, gt_nrm))
        worst = dict(WORST_CASE)
        if n_gt_edges == 0:
            worst.update(ecd=math.nan, ef1=math.nan)  # skipped in averages, as for any shape
        return {**worst, "n_gt_edge_points": n_gt_edges, "n_pred_edge_points": 0}
    return evaluate_samples(gt_pts, gt_nrm, *pred)


def chamfer_distance(pred_vertices, pred_faces, gt_vertices, gt_faces, *,
                     n_samples: int = N_SAMPLES, seed: int = 0, check=None) -> float:
    """``evaluate(...)["cd"]`` alone: the same samples, so the same value, without the normal
    and edge metrics (most of ``evaluate``'s time); ``check()`` runs between its steps (e.g.
    raises ``CancelledError`` when a run is cancelled)."""
    gt_pts, _, pred = _normalised_samples(pred_vertices, pred_faces, gt_vertices, gt_faces,
                                          n_samples, seed, check)
    if pred is None:
        return float(WORST_CASE["cd"])
    pred_pts = pred[0]
    if check is not None:
        check()
    d_gp = cKDTree(pred_pts).query(gt_pts)[0]
    if check is not None:
        check()
    d_pg = cKDTree(gt_pts).query(pred_pts)[0]
    return float(np.mean(d_gp**2) + np.mean(d_pg**2))  # as evaluate_samples


def _normalised_samples(pred_vertices, pred_faces, gt_vertices, gt_faces, n_samples: int,
                        seed: int, check=None):
    """Samples of both surfaces in the ground truth's normalised frame: (gt points, gt normals,
    (pred points, pred normals) or None when the prediction has no surface). ``check()`` runs
    before each chunk of triangles of both surfaces (sampling a dense source is most of a
    distance's time)."""
    center, scale = normalization(gt_vertices)
    gt_v = (np.asarray(gt_vertices, dtype=np.float64) - center) / scale
    pred_v = (np.asarray(pred_vertices, dtype=np.float64).reshape(-1, 3) - center) / scale
    pred_f = np.asarray(pred_faces, dtype=np.int64).reshape(-1, 3)
    rng = np.random.default_rng(seed)
    gt_pts, gt_nrm = sample_surface(gt_v, gt_faces, n_samples, rng, check)
    if not _has_area(pred_v, pred_f, check):
        return gt_pts, gt_nrm, None
    return gt_pts, gt_nrm, sample_surface(pred_v, pred_f, n_samples, rng, check)


def format_row(metrics: dict) -> dict:
    """A copy of ``metrics`` in the paper's reporting units (CD x 10^5, ECD x 10^2)."""
    return {k: v * REPORT_SCALE[k] if k in REPORT_SCALE else v for k, v in metrics.items()}


def summarize(rows: list[dict]) -> dict:
    """NaN-aware mean of every numeric key over the rows (NaN where no row has a value).

    Args:
        rows: per-shape metric dicts (e.g. from ``evaluate``); keys may differ between rows.

    Returns:
        dict mapping each numeric key to the mean of its non-NaN values.
    """
    keys = dict.fromkeys(k for row in rows for k, v in row.items()
                         if isinstance(v, (int, float, np.number)) and not isinstance(v, bool))
    out = {}
    for key in keys:
        vals = np.array([row[key] for row in rows if key in row], dtype=np.float64)
        vals = vals[~np.isnan(vals)]
        out[key] = float(vals.mean()) if len(vals) else math.nan
    return out
