"""Bilateral normal filtering: a feature-preserving denoise of a network's mesh.

A network's vertices carry a little independent noise from cell to cell (~0.1-0.2 voxel). On a
flat or gently curved face that noise tilts each small triangle a different way: the face
looks crumpled, its normals disagree with the true surface's, and the edge metrics count the
tilted triangles as false creases. Plain smoothing (Laplacian, Taubin) removes the noise but
also rounds the creases the network placed. Bilateral normal filtering (Zheng et al., "Bilateral
normal filtering for mesh denoising", TVCG 2011) denoises the *face normals* instead: each
face's normal becomes an average of its neighbours' normals weighted by their area, their
distance and -- the bilateral part -- by how much their normal already agrees with its own. A
face across a crease (normals tens of degrees apart) gets almost no weight, so creases stay
sharp while the faces on either side flatten. The vertices then move to fit the filtered normals
(the iterative update of Sun et al., "Fast and effective feature-preserving mesh denoising",
TVCG 2007): each vertex moves by the mean, over its faces, of its distance to the face's plane
(through the face's centroid, along the filtered normal), so vertices move only across the
surface, never along it.

The update runs fewer passes on detail (``vertex_passes``): where the filtered normals bend by
a few degrees within a vertex's faces, away from creases and from the planar faces an earlier
stage placed, the surface is curved at the scale of a cell or two -- wrinkles as tall as the
noise -- and the full update would smooth them away.

A mesh that is wrinkled all over (``wrinkled_surface``: few vertices on planar patches and a
middle share on detail, as a scanned organic shape at 64^3) keeps the network's vertices: there
the wrinkles are the surface, the filter sharpens them into facets, and each such shape of the
validation families came out 1-11 % worse on CD with it, while every other kind gained.

Faces and their order are kept: the mesh's topology, and so its closed 2-manifoldness, are
unchanged. ``filter_mesh`` is the vectorised entry; ``filter_mesh_naive`` is the slow, obviously
correct reference that loops over faces and vertices (tests compare the two).

The parameters (``NormalFilter``) were chosen on generated validation shapes (not the dev
meshes); docs/experiments/normal-filter.md has the measurements.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from .voxelize import triangle_cross


@dataclass(frozen=True)
class NormalFilter:
    #: width of the normal-difference Gaussian, in |n_i - n_j| (0.3 ~ 17 degrees): faces whose
    #: normals differ by much more than this are on the other side of a crease
    sigma_normal: float = 0.3
    #: passes of normal averaging (each widens the neighbourhood by a ring of faces)
    normal_iterations: int = 4
    #: passes of the vertex update towards the filtered normals
    vertex_iterations: int = 10
    #: passes for the vertices on detail: where the filtered normals bend by more than
    #: ``detail_degrees`` within a vertex's faces, the surface is curved at the scale of a cell
    #: or two (wrinkles, folds), as tall as the network's noise, and the full update smooths
    #: it away; a few passes remove the cell-to-cell jitter and keep most of it
    detail_vertex_iterations: int = 3
    #: spread (degrees) of a vertex's filtered face normals about their mean above which it is
    #: on detail; ``detail_rings`` rings around such vertices count as detail too
    detail_degrees: float = 5.0
    detail_rings: int = 1
    #: spread above which a vertex is on a crease: creases, the vertices an earlier stage put on
    #: a planar face (``filter_mesh``'s ``planar_v``) and ``planar_rings`` rings around both
    #: take all ``vertex_iterations``, detail or not
    crease_degrees: float = 30.0
    planar_rings: int = 1
    #: a wrinkled surface (left as the network made it): under this share of the vertices on
    #: planar patches (a machined or printed part has more) ...
    wrinkled_planar_share: float = 0.07
    #: ... and a share of vertices on detail (spread above ``detail_degrees``) in this range
    #: (smooth shapes have less; a tube curved at the scale of a cell, like a knot, more)
    wrinkled_detail_share: tuple[float, float] = (0.4, 0.9)


DEFAULT = NormalFilter()


def filter_mesh(vertices_vx3: np.ndarray, faces_fx3: np.ndarray,
                params: NormalFilter = DEFAULT, fixed_vx3: np.ndarray | None = None,
                check=None, planar_v: np.ndarray | None = None) -> np.ndarray:
    """Denoise a triangle mesh, keeping its creases: (V, 3) float64 -> (V, 3) float64.

    Args:
        vertices_vx3: (V, 3) float vertices; faces_fx3: (F, 3) int faces (any orientation,
            consistent). Vertices used by no face are returned unchanged.
        params: the filter's widths and pass counts.
        fixed_vx3: optional (V, 3) bool, coordinates that must not move (a flat face or a
            bounding plane that an earlier stage placed: ``flatpatches.pinned_coordinates``).
        check: called before every pass (e.g. raises ``CancelledError`` when a run is
            cancelled: a pass takes well under a second even at 256³).
        planar_v: optional (V,) bool, vertices an earlier stage placed on planar faces. When
            given, vertices on detail stop after ``params.detail_vertex_iterations`` passes
            (``vertex_passes``) and a wrinkled surface is returned as it came
            (``wrinkled_surface``); None: every vertex takes all ``params.vertex_iterations``.

    Returns:
        (V, 3) float64 new vertex positions; the faces index them unchanged.
    """
    vertices = np.asarray(vertices_vx3, dtype=np.float64)
    faces = np.asarray(faces_fx3, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        return vertices.copy()
    original, incidence, normals = filtered_normals(vertices, faces, params, check)
    passes = None
    if planar_v is not None:
        spread = normal_spread(faces, incidence, normals)
        if wrinkled_surface(spread, planar_v, params):
            return vertices.copy()
        passes = vertex_passes(faces, incidence, normals, planar_v, params, spread)
    return fit_vertices(vertices, faces, incidence, normals, original, params.vertex_iterations,
                        fixed_vx3, check, passes)


def filtered_normals(vertices: np.ndarray, faces: np.ndarray, params: NormalFilter = DEFAULT,
                     check=None):
    """The filter's first half on (V, 3) float64 ``vertices`` and (F, 3) int64 ``faces``:
    (original (F, 3) unnormalised face normals, (V, F) ``vertex_faces`` incidence, (F, 3)
    bilaterally filtered unit normals)."""
    original, areas, centroids = face_geometry(vertices, faces)
    incidence = vertex_faces(faces, len(vertices))
    normals = bilateral_normals(original, areas, centroids, face_neighbours(incidence), params,
                                check)
    return original, incidence, normals


def normal_spread(faces, incidence, normals) -> np.ndarray:
    """(V,) float: the largest angle (degrees) between a vertex's faces' (F, 3) ``normals``
    and their mean (0 for a vertex of no face)."""
    mean = incidence @ normals  # (V, 3)
    mean /= np.maximum(np.sqrt(_dot(mean, mean)), 1e-12)[:, None]
    corner = faces.ravel()  # (3F,) the vertex of each face corner
    cosine = _dot(np.repeat(normals, 3, axis=0), mean[corner])  # (3F,)
    lowest = np.ones(incidence.shape[0])
    np.minimum.at(lowest, corner, cosine)
    return np.degrees(np.arccos(np.clip(lowest, -1.0, 1.0)))


def wrinkled_surface(spread: np.ndarray, planar_v: np.ndarray,
                     params: NormalFilter = DEFAULT) -> bool:
    """True for a mesh wrinkled all over, which the filter leaves alone: under
    ``params.wrinkled_planar_share`` of its vertices on planar patches (``planar_v``), and a
    share within ``params.wrinkled_detail_share`` whose (V,) filtered-normal ``spread``
    (``normal_spread``) exceeds ``params.detail_degrees``. Chosen on the validation family and
    checked on a second draw of it (docs/experiments/normal-filter.md, "No filter on wrinkled
    surfaces")."""
    if len(spread) == 0 or np.mean(planar_v) >= params.wrinkled_planar_share:
        return False
    low, high = params.wrinkled_detail_share
    return bool(low <= np.mean(spread > params.detail_degrees) <= high)


def vertex_passes(faces, incidence: sp.csr_matrix, normals, planar_v: np.ndarray,
                  params: NormalFilter = DEFAULT, spread: np.ndarray | None = None) -> np.ndarray:
    """(V,) int vertex-update passes of each vertex, from the (F, 3) filtered ``normals``
    (``spread``: their ``normal_spread``, computed here when None).

    Detail vertices -- whose faces' normals spread between ``params.detail_degrees`` and
    ``params.crease_degrees`` about their mean, and ``params.detail_rings`` rings around them --
    take ``params.detail_vertex_iterations``, unless they lie within ``params.planar_rings``
    rings of a ``planar_v`` vertex or of a crease vertex (spread above ``crease_degrees``).
    Every other vertex takes ``params.vertex_iterations``: on planes and at creases the noise
    is all there is to remove, and on surfaces curved over many cells (a vase, a cylinder, the
    same wrinkles at twice the resolution) the full update removes noise and keeps the shape
    (docs/experiments/normal-filter.md, "Lighter on detail")."""
    linked = (incidence @ incidence.T).tocsr()  # (V, V) nonzero where two vertices share a face

    def grow(mask, rings):
        for _ in range(rings):
            mask = (linked @ mask.astype(np.float64)) > 0
        return mask

    if spread is None:
        spread = normal_spread(faces, incidence, normals)
    crease = spread > params.crease_degrees
    detail = grow((spread > params.detail_degrees) & ~crease, params.detail_rings)
    light = detail & ~grow(np.asarray(planar_v, dtype=bool) | crease, params.planar_rings)
    return np.where(light, params.detail_vertex_iterations, params.vertex_iterations)


def face_geometry(vertices: np.ndarray, faces: np.ndarray):
    """Unit normals (F, 3), areas (F,) and centroids (F, 3) of the faces (a zero-area face
    gets a zero normal, so it neither pulls on its neighbours nor moves its vertices)."""
    cross = triangle_cross(vertices[faces])  # (F, 3)
    length = np.sqrt(_dot(cross, cross))
    normals = np.divide(cross, length[:, None], out=np.zeros_like(cross),
                        where=length[:, None] > 0)
    return normals, 0.5 * length, face_centroids(vertices, faces)


def face_centroids(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(F, 3) centroids of the faces."""
    a, b, c = vertices[faces[:, 0]], vertices[faces[:, 1]], vertices[faces[:, 2]]  # (F, 3)
    return (a + b + c) / 3.0


#: face pairs per chunk of the pairwise distances
PAIR_CHUNK = 1 << 20


def _pairwise(function, n: int, out: np.ndarray | None = None) -> np.ndarray:
    """(n,) float64: ``function(a, b)`` evaluated on consecutive chunks of the pairs (into
    ``out`` when given)."""
    out = np.empty(n, dtype=np.float64) if out is None else out

    def fill(a, b):
        out[a:b] = function(a, b)

    _in_chunks(n, fill)
    return out


def _in_chunks(n: int, work) -> None:
    """``work(a, b)`` on consecutive chunks of ``PAIR_CHUNK`` pairs."""
    for a in range(0, n, PAIR_CHUNK):
        work(a, min(a + PAIR_CHUNK, n))


def _sq_norm(u: np.ndarray) -> np.ndarray:
    return _dot(u, u)


def _dot(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Row-wise dot products of two (N, 3) arrays: (N,)."""
    return np.einsum("ij,ij->i", u, v)


def face_neighbours(incidence: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """The pairs of faces sharing at least one vertex, each pair once, in the row of its
    lower-numbered face: CSR rows ``indptr`` (F + 1,) and ``neighbours`` (P,) int32 of the
    faces j > i linked to each face i, from the (V, F) ``vertex_faces`` incidence. A pair's
    weights are symmetric, so each normal pass computes them once for both faces (half the
    gathers of storing both directions); the structure is built once and every pass refills
    only its values: at 256³ P is ~5·10^6, and (P, 2) int64 pairs alone would be 80 MB."""
    counts = incidence.astype(np.int8)  # a face pair shares at most 3 vertices
    linked = sp.triu(counts.T @ counts, k=1, format="csr")  # j > i, linked through a vertex
    index_type = np.int32 if linked.nnz < np.iinfo(np.int32).max else np.int64
    return linked.indptr.astype(index_type), linked.indices.astype(index_type)


def vertex_faces(faces: np.ndarray, n_vertices: int) -> sp.csr_matrix:
    """(V, F) sparse incidence: 1 where vertex v is a corner of face f."""
    return sp.csr_matrix((np.ones(faces.size), (faces.ravel(), np.repeat(
        np.arange(len(faces)), 3))), shape=(n_vertices, len(faces)))


def bilateral_normals(normals, areas, centroids, neighbours, params: NormalFilter,
                      check=None) -> np.ndarray:
    """``params.normal_iterations`` passes of bilateral averaging of face normals.

    Each pass: n_i <- normalise(a_i n_i + sum_j a_j W_s(|c_i - c_j|) W_r(|n_i - n_j|) n_j) over
    the faces j sharing a vertex with i (``neighbours``: each pair once, as ``face_neighbours``
    gives them), with Gaussian W_s of width the mean centroid distance of the neighbours
    (scale-free) and W_r of width ``params.sigma_normal``. W_s W_r is symmetric: with G the
    matrix of its pairs j > i, the sum is (G + G^T) (a n).
    """
    indptr, j = neighbours
    n_faces = len(normals)
    if len(j) == 0:
        return normals
    i = np.repeat(np.arange(n_faces, dtype=j.dtype), np.diff(indptr))  # (P,) row of each pair
    # pair quantities are computed in chunks and in place (5·10^6 pairs at 256³: every (P,)
    # float64 temporary is 40 MB, a (P, 3) one 120 MB)
    spatial = _pairwise(lambda a, b: _sq_norm(centroids[i[a:b]] - centroids[j[a:b]]), len(i))
    np.divide(spatial, -2.0 * np.mean(spatial), out=spatial)
    np.exp(spatial, out=spatial)
    upper = sp.csr_matrix((np.empty(len(j)), j, indptr), shape=(n_faces, n_faces))  # G
    for _ in range(params.normal_iterations):
        if check is not None:
            check()
        agreement = _pairwise(lambda a, b, n=normals: _sq_norm(n[i[a:b]] - n[j[a:b]]), len(i),
                              out=upper.data)
        np.divide(agreement, -2.0 * params.sigma_normal ** 2, out=agreement)
        np.exp(agreement, out=agreement)
        agreement *= spatial
        weighted = areas[:, None] * normals  # (F, 3)
        summed = weighted + upper @ weighted + upper.T @ weighted  # (F, 3)
        length = np.sqrt(_dot(summed, summed))[:, None]
        normals = np.divide(summed, length, out=np.zeros_like(summed), where=length > 0)
    return normals


def fit_vertices(vertices, faces, incidence, normals, original, iterations: int,
                 fixed=None, check=None, passes=None) -> np.ndarray:
    """Move each vertex towards the planes of its faces: x_v += mean over faces f of v of
    n_f (n_f . (c_f - x_v)), with c_f the face's current centroid, ``iterations`` times; the
    ``fixed`` (V, 3) coordinates do not move, a vertex stops after its ``passes`` (V,) int
    passes if given, and no face turns against its ``original`` (F, 3) normal
    (``keep_orientation``). ``incidence``: the (V, F) ``vertex_faces``.

    The sum splits into sum_f n_f (n_f . c_f) - (sum_f n_f n_f^T) x_v: the 3 x 3 matrices are
    fixed (the normals do not change), so each pass is one sparse product and a batched
    matrix-vector product."""
    n_vertices, n_faces = len(vertices), len(faces)
    # row v of the incidence sums over the faces of vertex v
    degree = np.maximum(np.asarray(incidence.sum(axis=1)), 1.0)  # (V, 1)
    if fixed is not None:
        degree = np.where(fixed, np.inf, degree)  # (V, 3): a fixed coordinate's step is 0
    outer = (incidence @ (normals[:, :, None] * normals[:, None, :]).reshape(n_faces, 9))
    outer = outer.reshape(n_vertices, 3, 3)  # (V, 3, 3) sum of n n^T over each vertex's faces
    for k in range(iterations):
        if check is not None:
            check()
        centroids = face_centroids(vertices, faces)  # (F, 3)
        pull = incidence @ (normals * _dot(normals, centroids)[:, None])  # (V, 3)
        step = pull - np.einsum("vij,vj->vi", outer, vertices)  # (V, 3)
        if passes is not None:
            step[passes <= k] = 0.0  # this vertex's passes are done
        vertices = keep_orientation(vertices, vertices + step / degree, faces, original)
    return vertices


def keep_orientation(before, after, faces, original_normals) -> np.ndarray:
    """``after``, with the vertices of every face it turns over put back where ``before`` had
    them, until no face points against its original normal (a turned-over face is a fold in the
    surface; a small face beside a crease can turn over when its vertices move by more than its
    size). Terminates: at worst every vertex returns to ``before``, which folded nothing."""
    after = after.copy()
    while True:
        turned = _dot(triangle_cross(after[faces]), original_normals) < 0  # (F,)
        back = np.unique(faces[turned])
        back = back[np.any(after[back] != before[back], axis=1)]
        if len(back) == 0:
            return after
        after[back] = before[back]


def filter_mesh_naive(vertices_vx3, faces_fx3, params: NormalFilter = DEFAULT,
                      fixed_vx3=None, planar_v=None) -> np.ndarray:
    """``filter_mesh`` written face by face and vertex by vertex (slow; for tests)."""
    vertices = np.array(vertices_vx3, dtype=np.float64)
    faces = [tuple(int(k) for k in face) for face in np.asarray(faces_fx3).reshape(-1, 3)]
    if not faces:
        return vertices
    normals, areas, centroids, original = [], [], [], []
    for a, b, c in faces:
        cross = np.cross(vertices[b] - vertices[a], vertices[c] - vertices[a])
        original.append(cross)
        length = np.linalg.norm(cross)
        normals.append(cross / length if length > 0 else np.zeros(3))
        areas.append(0.5 * length)
        centroids.append((vertices[a] + vertices[b] + vertices[c]) / 3.0)
    faces_of = {}
    for f, face in enumerate(faces):
        for v in face:
            faces_of.setdefault(v, set()).add(f)
    neighbours = [sorted(set().union(*(faces_of[v] for v in face)) - {f})
                  for f, face in enumerate(faces)]
    distances_sq = [np.sum((centroids[f] - centroids[g]) ** 2)
                    for f in range(len(faces)) for g in neighbours[f]]
    sigma_s_sq = np.mean(distances_sq) if distances_sq else 1.0
    for _ in range(params.normal_iterations):
        new = []
        for f in range(len(faces)):
            total = areas[f] * normals[f]
            for g in neighbours[f]:
                spatial = areas[g] * np.exp(-np.sum((centroids[f] - centroids[g]) ** 2)
                                            / (2 * sigma_s_sq))
                agreement = np.exp(-np.sum((normals[f] - normals[g]) ** 2)
                                   / (2 * params.sigma_normal ** 2))
                total = total + spatial * agreement * normals[g]
            length = np.linalg.norm(total)
            new.append(total / length if length > 0 else np.zeros(3))
        normals = new
    passes = {v: params.vertex_iterations for v in faces_of}
    if planar_v is not None:
        spread = {}
        for v, its_faces in faces_of.items():
            mean = sum(normals[f] for f in its_faces)
            mean = mean / max(np.linalg.norm(mean), 1e-12)
            lowest = min(float(np.dot(normals[f], mean)) for f in its_faces)
            spread[v] = np.degrees(np.arccos(min(max(lowest, -1.0), 1.0)))

        def grow(vertex_set, rings):  # breadth-first, a ring at a time
            vertex_set = set(vertex_set)
            for _ in range(rings):
                vertex_set |= {u for v in vertex_set for f in faces_of[v] for u in faces[f]}
            return vertex_set

        on_detail = sum(1 for v in faces_of if spread[v] > params.detail_degrees)
        planar_count = sum(1 for v in range(len(vertices)) if planar_v[v])
        low, high = params.wrinkled_detail_share
        if planar_count < params.wrinkled_planar_share * len(vertices) \
                and low * len(vertices) <= on_detail <= high * len(vertices):
            return vertices  # a wrinkled surface: the network's vertices as they are
        crease = {v for v in faces_of if spread[v] > params.crease_degrees}
        detail = grow({v for v in faces_of if params.detail_degrees < spread[v]} - crease,
                      params.detail_rings)
        kept = grow({v for v in faces_of if planar_v[v]} | crease, params.planar_rings)
        passes = {v: params.detail_vertex_iterations if v in detail - kept
                  else params.vertex_iterations for v in faces_of}
    for k in range(params.vertex_iterations):
        moved = vertices.copy()
        for v, its_faces in faces_of.items():
            if passes[v] <= k:
                continue
            step = np.zeros(3)
            for f in its_faces:
                centroid = vertices[list(faces[f])].mean(axis=0)
                step += normals[f] * np.dot(normals[f], centroid - vertices[v])
            for axis in range(3):
                if fixed_vx3 is None or not fixed_vx3[v][axis]:
                    moved[v][axis] = vertices[v][axis] + step[axis] / len(its_faces)
        while True:  # put back the vertices of faces that turned over (keep_orientation)
            back = [v for f, face in enumerate(faces) if _turned(moved, face, original[f])
                    for v in face if np.any(moved[v] != vertices[v])]
            if not back:
                break
            for v in back:
                moved[v] = vertices[v]
        vertices = moved
    return vertices


def _turned(vertices, face, original_normal) -> bool:
    a, b, c = face
    return float(np.dot(np.cross(vertices[b] - vertices[a], vertices[c] - vertices[a]),
                        original_normal)) < 0
