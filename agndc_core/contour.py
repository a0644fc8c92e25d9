"""Dual contouring: per-cell vertices + edge occupancies -> triangle mesh (UNDC topology).

Every occupied lattice edge becomes the quad of the four cells around it, split into two
triangles. With binary input the two end points of a crossed edge tell inside from outside, so
each quad is oriented to face from the inside end point to the outside one (outward for solids).

``dual_contour`` is a short pipeline of named, vectorised stages; ``contour_naive.py`` holds the
slow cell-by-cell reference that tests compare against exactly (same vertex order, same faces).
Coordinates are lattice coordinates (grid.py): the vertex of cell c is ``c + offset``.
"""

from __future__ import annotations

import numpy as np

#: For axis a, the two other axes in cyclic order: quads listed in this order face +a.
OTHER_AXES = ((1, 2), (2, 0), (0, 1))


def dual_contour(vertex_dx3: np.ndarray, edge_dx3: np.ndarray, inside: np.ndarray | None = None, *,
                 min_component_faces: int = 0, merge_vertices: bool = False):
    """Contour a lattice of dual vertices and occupied edges.

    Args:
        vertex_dx3: (Dx, Dy, Dz, 3) float offsets of each cell's vertex from its min corner
            (clipped into [0, 1]).
        edge_dx3: (Dx, Dy, Dz, 3) bool, edge from point p along +axis is crossed.
        inside: optional (Dx, Dy, Dz) bool point occupancy, used to orient the quads outward.
            Edges whose end points agree (only possible with predicted edges) keep the +axis order.
        min_component_faces: drop connected components with fewer faces than this.
        merge_vertices: merge vertices that coincide (e.g. cells whose vertices were clipped
            onto a shared face).

    Returns:
        vertices: (V, 3) float64 lattice coordinates; faces: (F, 3) int64. Empty input gives
        zero-size arrays of these shapes.
    """
    points, axes = _occupied_edges(edge_dx3)
    quads = _quad_cells(points, axes)  # (E, 4, 3)
    quads = _orient_quads(quads, points, axes, inside)
    vertices, quad_ids = _compact_vertices(quads, vertex_dx3)
    faces = _split_quads(quad_ids, vertices)
    if merge_vertices:
        vertices, faces = _merge_vertices(vertices, faces)
    if min_component_faces > 0:
        vertices, faces = drop_small_components(vertices, faces, min_component_faces)
    return vertices, faces


def _occupied_edges(edge_dx3: np.ndarray):
    """Crossed edges that have four neighbouring cells: (E, 3) int points and (E,) int axes.

    Order: by axis, then C order of the point, the order the naive reference visits them.
    """
    dims = np.array(edge_dx3.shape[:3])
    points, axes = [], []
    for axis, (b, c) in enumerate(OTHER_AXES):
        found = np.argwhere(edge_dx3[..., axis])  # (n, 3), C order
        # the quad needs cells p - e_b - e_c .. p, and cell p needs its far corner p + 1
        ok = (found[:, b] >= 1) & (found[:, c] >= 1)
        ok &= (found[:, b] <= dims[b] - 2) & (found[:, c] <= dims[c] - 2)
        ok &= found[:, axis] <= dims[axis] - 2
        points.append(found[ok])
        axes.append(np.full(int(ok.sum()), axis))
    return np.concatenate(points).astype(np.int64), np.concatenate(axes).astype(np.int64)


def _quad_cells(points: np.ndarray, axes: np.ndarray) -> np.ndarray:
    """(E, 4, 3) cells around each edge: p - e_b - e_c, p - e_c, p, p - e_b (faces +axis)."""
    unit = np.eye(3, dtype=np.int64)
    e_b = unit[[OTHER_AXES[a][0] for a in range(3)]][axes]  # (E, 3)
    e_c = unit[[OTHER_AXES[a][1] for a in range(3)]][axes]
    return np.stack([points - e_b - e_c, points - e_c, points, points - e_b], axis=1)


def _orient_quads(quads, points, axes, inside):
    """Reverse the quads whose inside end point is the far one (their surface faces -axis)."""
    if inside is None or len(points) == 0:
        return quads
    far = points + np.eye(3, dtype=np.int64)[axes]
    near_in = inside[tuple(points.T)]
    far_in = inside[tuple(far.T)]
    flip = far_in & ~near_in
    quads = quads.copy()
    quads[flip] = quads[flip][:, ::-1]
    return quads


def _compact_vertices(quads: np.ndarray, vertex_dx3: np.ndarray):
    """One vertex per used cell, numbered in C order of the cells.

    Returns:
        vertices: (V, 3) float64 = cell + clipped offset; quad_ids: (E, 4) int64.
    """
    shape = vertex_dx3.shape[:3]
    if len(quads) == 0:
        return np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64)
    flat = np.ravel_multi_index(quads.reshape(-1, 3).T, shape)
    used, inverse = np.unique(flat, return_inverse=True)
    cells = np.stack(np.unravel_index(used, shape), axis=1)
    offsets = np.clip(vertex_dx3.reshape(-1, 3)[used].astype(np.float64), 0.0, 1.0)
    return cells + offsets, inverse.reshape(-1, 4).astype(np.int64)


def _split_quads(quad_ids: np.ndarray, vertices: np.ndarray) -> np.ndarray:
    """Split each quad (a, b, c, d) along its shorter diagonal: (2E, 3) triangles."""
    a, b, c, d = quad_ids.T
    diag_ac = np.linalg.norm(vertices[a] - vertices[c], axis=1)
    diag_bd = np.linalg.norm(vertices[b] - vertices[d], axis=1)
    use_ac = diag_ac <= diag_bd
    first = np.where(use_ac[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    second = np.where(use_ac[:, None], np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    # interleave so the two triangles of a quad stay together
    return np.stack([first, second], axis=1).reshape(-1, 3).astype(np.int64)


def _merge_vertices(vertices: np.ndarray, faces: np.ndarray, digits: int = 6):
    """Merge coincident vertices and drop faces that collapse."""
    if len(vertices) == 0:
        return vertices, faces
    keys = np.round(vertices, digits)
    unique, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # keep the original vertex order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    faces = rank[inverse.reshape(-1)][faces]
    ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return vertices[first[order]], faces[ok]


def face_components(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    """(F,) int label of the connected component (through shared vertices) of each face."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    if len(faces) == 0:
        return np.zeros(0, dtype=np.int64)
    # faces and vertices as one bipartite graph: faces are connected through shared vertices
    n_faces = len(faces)
    rows = np.repeat(np.arange(n_faces), 3)
    full = coo_matrix((np.ones(rows.size), (rows, n_faces + faces.reshape(-1))),
                      shape=(n_faces + n_vertices,) * 2)
    _, labels = connected_components(full, directed=False)
    return labels[:n_faces]


def drop_small_components(vertices, faces, min_faces: int):
    """Remove connected components with fewer than ``min_faces`` faces; unused vertices go too."""
    labels = face_components(faces, len(vertices))
    sizes = np.bincount(labels) if len(labels) else np.zeros(0, dtype=np.int64)
    faces = faces[sizes[labels] >= min_faces] if len(faces) else faces
    used = np.unique(faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces]
