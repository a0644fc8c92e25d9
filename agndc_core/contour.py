"""Dual contouring: per-cell vertices + edge occupancies -> triangle mesh (UNDC topology).

Every occupied lattice edge becomes the quad of the four cells around it, split into two
triangles. With binary input the two end points of a crossed edge tell inside from outside, so
each quad is oriented to face from the inside end point to the outside one (outward for solids).

**Manifold output** (when ``inside`` is given). One vertex per cell glues surfaces that only touch
along a voxel edge or at a voxel corner. Instead, each cell gets one vertex per *surface patch*:
its 8 corners are grouped into inside components (6-connected: along the 12 cube edges) and
outside components (18-connected: cube edges and face diagonals, not body diagonals), and a
crossed edge belongs to the patch (inside component, outside component) of its two end points.
An ambiguous face (inside corners on one diagonal) thereby separates its inside corners and joins
its outside ones in *both* cells that share it, so neighbours agree, and every patch is a disk with
one boundary loop (checked in the tests for all 256 cases). One configuration needs more: a face
whose two inside corners are joined through the interior of both cells that share it. The surface
is then a thin tube through the face (the outside passes between the inside corners), which two
cell vertices cannot span (their edge would carry four faces); each of the face's two boundary
segments gets a vertex of its own on the face (``_tube_vertices``), which splits one triangle of
each of the face's four quads in two. The result is a closed, oriented 2-manifold whose
components are the surfaces between 6-connected inside and 18-connected outside regions.

``dual_contour`` is a short pipeline of named, vectorised stages; ``contour_naive.py`` holds the
slow cell-by-cell reference that tests compare against exactly (same vertex order, same faces).
Coordinates are lattice coordinates (grid.py): the vertex of cell c is ``c + offset``.
"""

from __future__ import annotations

import numpy as np

from .errors import AGNDCError
from .grid import CELL_EDGES as EDGE_STARTS  # the one definition of a cell's 12 edges
from .grid import OTHER_AXES
from .tolerances import tol


class ContourError(AGNDCError, ValueError):
    """Inputs of ``dual_contour`` that contradict each other."""


# --- the cell tables: corners, edges and faces of one cell, and the patches of its 256 cases ---

#: (8, 3) offset of corner k from the cell's min corner: k = x + 2 y + 4 z
CORNERS = np.array([[(k >> d) & 1 for d in range(3)] for k in range(8)], dtype=np.int64)


def _corner_index(offset) -> int:
    return int(offset[0]) + 2 * int(offset[1]) + 4 * int(offset[2])


def _cell_edges() -> np.ndarray:
    """(12, 2) end corners of the cell edges; edge 4 a + 2 db + dc runs along axis a from the
    corner db e_b + dc e_c ((b, c) = OTHER_AXES[a])."""
    edges = []
    for axis, start in EDGE_STARTS:
        end = np.array(start)
        end[axis] = 1
        edges.append((_corner_index(start), _corner_index(end)))
    return np.array(edges, dtype=np.int64)


def _cell_faces() -> np.ndarray:
    """(6, 4) corners of cell face 2 n + side (normal axis n, side 0 = low), in cyclic order."""
    faces = []
    for n, (b, c) in enumerate(OTHER_AXES):
        for side in (0, 1):
            ring = []
            for db, dc in ((0, 0), (1, 0), (1, 1), (0, 1)):
                offset = np.zeros(3, dtype=np.int64)
                offset[n], offset[b], offset[c] = side, db, dc
                ring.append(_corner_index(offset))
            faces.append(ring)
    return np.array(faces, dtype=np.int64)


CELL_EDGES = _cell_edges()
CELL_FACES = _cell_faces()
#: (12, 3) midpoint of each cell edge, relative to the cell's min corner
EDGE_MIDPOINTS = (CORNERS[CELL_EDGES[:, 0]] + CORNERS[CELL_EDGES[:, 1]]) / 2.0


def _components(n_nodes: int, links) -> np.ndarray:
    """(n_nodes,) label = smallest node of its component, for an undirected list of links."""
    label = list(range(n_nodes))
    changed = True
    while changed:  # tiny graphs (8 nodes): relax until stable
        changed = False
        for u, v in links:
            low = min(label[u], label[v])
            if label[u] != low or label[v] != low:
                label[u] = label[v] = low
                changed = True
    return np.array(label, dtype=np.int64)


def cell_patches(config: int) -> np.ndarray:
    """(12,) patch id of each cell edge for corner configuration ``config`` (bit k: corner k
    inside), -1 where the edge is not crossed. Patches are numbered in order of their first edge.

    Inside corners are linked along cube edges (6-connectivity), outside corners along cube edges
    and face diagonals (18-connectivity); a crossed edge's patch is the pair of components of
    its inside and its outside end point.
    """
    inside = [(config >> k) & 1 == 1 for k in range(8)]
    cube = [tuple(e) for e in CELL_EDGES]
    diagonals = [(f[0], f[2]) for f in CELL_FACES] + [(f[1], f[3]) for f in CELL_FACES]
    in_label = _components(8, [(u, v) for u, v in cube if inside[u] and inside[v]])
    out_label = _components(8, [(u, v) for u, v in cube + diagonals
                                if not inside[u] and not inside[v]])
    patches: dict[tuple[int, int], int] = {}
    ids = np.full(12, -1, dtype=np.int64)
    for edge, (u, v) in enumerate(cube):
        if inside[u] == inside[v]:
            continue
        key = (in_label[u], out_label[v]) if inside[u] else (in_label[v], out_label[u])
        ids[edge] = patches.setdefault(key, len(patches))
    return ids


def _patch_tables():
    """Tables over the 256 corner configurations, built from ``cell_patches``.

    Returns:
        patch: (256, 12) int8 patch of each cell edge (-1: not crossed);
        count: (256,) int64 number of patches;
        shift: (256, P, 3) float64 the patch's surface-nets point (mean of its crossed-edge
            midpoints) minus the whole cell's surface-nets offset as ``surface_nets_lattice``
            computes it (float32);
        joined: (256, 6) bool, face 2 n + side is ambiguous (4 crossed edges) and its two inside
            corners are in one inside component of the cell.
    """
    patch = np.stack([cell_patches(config) for config in range(256)])
    count = patch.max(axis=1) + 1
    shift = np.zeros((256, max(int(count.max()), 1), 3))
    joined = np.zeros((256, 6), dtype=bool)
    face_edges = _face_edges()
    for config in range(256):
        crossed = patch[config] >= 0
        if not crossed.any():
            continue
        cell_mean = np.float32(EDGE_MIDPOINTS[crossed].mean(axis=0)).astype(np.float64)
        for p in range(count[config]):
            shift[config, p] = EDGE_MIDPOINTS[patch[config] == p].mean(axis=0) - cell_mean
        for face in range(6):
            ids = patch[config, face_edges[face]]
            # the ambiguous face's edges alternate between its two inside corners' segments;
            # one patch for all four means the inside corners are joined through the cell
            joined[config, face] = bool(np.all(ids >= 0) and np.all(ids == ids[0]))
    return patch.astype(np.int8), count.astype(np.int64), shift, joined


def _face_edges() -> np.ndarray:
    """(6, 4) cell edges around each cell face, in the face's cyclic order."""
    lookup = {frozenset(map(int, e)): i for i, e in enumerate(CELL_EDGES)}
    return np.array([[lookup[frozenset((int(f[i]), int(f[(i + 1) % 4])))] for i in range(4)]
                     for f in CELL_FACES], dtype=np.int64)


PATCH, PATCH_COUNT, PATCH_SHIFT, FACE_JOINED = _patch_tables()


def dual_contour(vertex_dx3: np.ndarray, edge_dx3: np.ndarray, inside: np.ndarray | None = None, *,
                 min_component_faces: int = 0, merge_vertices: bool = False,
                 face_quads: bool = False):
    """Contour a lattice of dual vertices and occupied edges.

    Args:
        vertex_dx3: (Dx, Dy, Dz, 3) float offsets of each cell's vertex from its min corner
            (clipped into [0, 1]); or a function of (C,) flat cell ids giving their (C, 3)
            offsets, for a field only the contoured cells need (e.g.
            ``surfacenets.surface_nets_cells``: a dense 256³ field is 200 MB).
        edge_dx3: (Dx, Dy, Dz, 3) bool, edge from point p along +axis is crossed.
        inside: optional (Dx, Dy, Dz) bool point occupancy. When given, ``edge_dx3`` must be its
            crossing parity (``labels.crossed_edges(inside)``, else ContourError); the quads face
            outward and the output is a closed 2-manifold (module docstring): a cell with
            several surface patches gets one vertex per patch, placed at the patch's own
            surface-nets point moved by the cell's correction (``vertex_dx3`` minus the cell's
            surface-nets offset). Without it: one vertex per cell, quads face +axis.
        min_component_faces: drop connected components with fewer faces than this.
        merge_vertices: merge vertices that coincide (e.g. cells whose vertices were clipped
            onto a shared face); this may undo the manifold split.
        face_quads: also return the quad (crossed lattice edge) each triangle comes from, so
            the triangles can be joined back into quads (``quads.py``).

    Returns:
        vertices: (V, 3) float64 lattice coordinates; faces: (F, 3) int64; with ``face_quads``
        also (F,) int64 quad id of each face (two faces per quad, three where a tube vertex
        splits one of them). Empty input gives zero-size arrays of these shapes.
    """
    if inside is not None:
        inside = np.asarray(inside, dtype=bool)
        _check_parity(edge_dx3, inside)
    points, axes = _occupied_edges(edge_dx3)
    quads = _quad_cells(points, axes)  # (E, 4, 3)
    if inside is None:
        vertices, quad_ids = _compact_vertices(quads, vertex_dx3, edge_dx3.shape[:3])
        faces = _split_quads(quad_ids, vertices)
        quad_of_face = np.repeat(np.arange(len(quad_ids)), 2)
    else:
        vertices, faces, quad_of_face = _contour_patches(quads, points, axes, vertex_dx3,
                                                         inside)
    if merge_vertices:
        vertices, faces, kept = _merge_vertices(vertices, faces)
        quad_of_face = quad_of_face[kept]
    if min_component_faces > 0:
        kept = large_component_faces(faces, len(vertices), min_component_faces)
        vertices, faces = _keep_faces(vertices, faces, kept)
        quad_of_face = quad_of_face[kept]
    if face_quads:
        return vertices, faces, quad_of_face.astype(np.int64)
    return vertices, faces


def _check_parity(edge_dx3: np.ndarray, inside: np.ndarray) -> None:
    """Patches come from the corner values, so the edges must be exactly their sign changes."""
    if inside.shape != edge_dx3.shape[:3]:
        raise ContourError(f"inside has shape {inside.shape}, the edges {edge_dx3.shape[:3]}")
    edge = np.asarray(edge_dx3, dtype=bool)
    differ = 0
    for axis in range(3):  # crossed_edges(inside) axis by axis, without the (D, 3) copy
        low, high, last = [slice(None)] * 3, [slice(None)] * 3, [slice(None)] * 3
        low[axis], high[axis], last[axis] = slice(0, -1), slice(1, None), -1
        parity = inside[tuple(low)] != inside[tuple(high)]
        differ += np.count_nonzero(edge[..., axis][tuple(low)] != parity)
        differ += np.count_nonzero(edge[..., axis][tuple(last)])
    if differ:
        raise ContourError(
            f"{differ} edges differ from the crossing parity of `inside`: manifold dual "
            "contouring needs edges = labels.crossed_edges(inside) (input topology); pass "
            "inside=None to contour predicted edges"
        )


def _contour_patches(quads, points, axes, vertex_dx3, inside):
    """The manifold path: one vertex per (cell, patch), plus a pair per tube face.

    Returns vertices (V, 3), faces (F, 3) and the (F,) quad of each face."""
    shape = inside.shape
    if len(quads) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64), np.zeros(0, dtype=np.int64)
    cells, cell_ids = _used_cells(quads, shape)  # (C,) flat, (E, 4)
    config = _cell_configs(cells, inside)  # (C,) uint8
    local = _quad_local_edges(axes)  # (E, 4) cell edge of each quad corner
    first = np.cumsum(PATCH_COUNT[config]) - PATCH_COUNT[config]  # (C,) first vertex of a cell
    quad_ids = first[cell_ids] + PATCH[config[cell_ids], local]  # (E, 4)
    vertices = _patch_vertices(cells, config, first, vertex_dx3, shape)
    tube_sides = _tube_sides(config, cell_ids, axes)  # (E, 4) bool
    extra, side_ids = _tube_vertices(tube_sides, quads, points, axes, inside, len(vertices))
    flip = _outward_flip(points, axes, inside)
    quad_ids[flip] = quad_ids[flip][:, ::-1]
    # reversing corners 0..3 maps side i (corners i, i+1) to old side 2 - i (mod 4)
    side_ids[flip] = side_ids[flip][:, [2, 1, 0, 3]]
    vertices = np.concatenate([vertices, extra])
    faces = _split_quads(quad_ids, vertices)
    # _split_tube_sides appends one triangle per tube side, in order of quad, then side
    quad_of_face = np.concatenate([np.repeat(np.arange(len(quads)), 2),
                                   np.nonzero(side_ids >= 0)[0]])
    return vertices, _split_tube_sides(faces, quad_ids, side_ids, vertices), quad_of_face


def _used_cells(quads: np.ndarray, shape) -> tuple[np.ndarray, np.ndarray]:
    """Flat ids (C,) of the cells the quads use, in C order, and (E, 4) index into them."""
    flat = np.ravel_multi_index(quads.reshape(-1, 3).T, shape)
    # a dense mark + rank over the lattice is several times faster than np.unique's sort
    used = np.zeros(int(np.prod(shape)), dtype=bool)
    used[flat] = True
    cells = np.flatnonzero(used)
    rank = np.zeros(used.size, dtype=np.int64)
    rank[cells] = np.arange(len(cells))
    return cells, rank[flat].reshape(-1, 4)


def _cell_configs(cells: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """(C,) uint8 corner configuration of each flat cell id: bit k = corner k is inside."""
    strides = np.array([inside.shape[1] * inside.shape[2], inside.shape[2], 1])
    flat_inside = np.asarray(inside, dtype=bool).reshape(-1)
    config = np.zeros(len(cells), dtype=np.uint8)
    for k, corner in enumerate(CORNERS @ strides):
        config |= flat_inside[cells + corner].astype(np.uint8) << k
    return config


def _quad_local_edges(axes: np.ndarray) -> np.ndarray:
    """(E, 4) edge index, inside each quad cell, of the quad's lattice edge.

    Quad corner j is cell p - db e_b - dc e_c with (db, dc) = (1, 1), (0, 1), (0, 0), (1, 0),
    so the edge leaves that cell's corner db e_b + dc e_c: cell edge 4 a + 2 db + dc.
    """
    return 4 * axes[:, None] + np.array([3, 1, 0, 2])


def _cell_offsets(vertex_dx3, cells: np.ndarray) -> np.ndarray:
    """(C, 3) float64 offsets of the flat cell ids from a dense field or a function of them."""
    if callable(vertex_dx3):
        return np.asarray(vertex_dx3(cells), dtype=np.float64)
    return vertex_dx3.reshape(-1, 3)[cells].astype(np.float64)


def _patch_vertices(cells, config, first, vertex_dx3, shape) -> np.ndarray:
    """(V, 3) float64 vertex of each (cell, patch): cells in C order, then patches in id order.

    A cell with one patch keeps ``cell + clip(offset)``; with several, each patch's vertex is its
    own surface-nets point plus the cell's correction (offset - the cell's surface-nets offset).
    """
    count = PATCH_COUNT[config]
    owner = np.repeat(np.arange(len(cells)), count)  # (V,) cell of each vertex
    patch = np.arange(len(owner)) - first[owner]
    offset = _cell_offsets(vertex_dx3, cells)[owner]
    several = count[owner] > 1
    offset[several] += PATCH_SHIFT[config[owner[several]], patch[several]]
    corner = np.stack(np.unravel_index(cells[owner], shape), axis=1)
    return corner + np.clip(offset, 0.0, 1.0)


#: quad side i joins corners i and i + 1 (mod 4) across a face; per side: which other axis it
#: steps along (0: b, 1: c), the face's side (0 low, 1 high) in corner i's cell, and the corner
#: whose cell lies on the face's high side
_SIDE_AXIS_SLOT = np.array([0, 1, 0, 1])  # side i steps along b (0) or c (1)
_SIDE_FROM = np.array([1, 1, 0, 0])
_SIDE_HIGHER = np.array([1, 2, 2, 3])


def _side_normals(axes: np.ndarray) -> np.ndarray:
    """(E, 4) normal axis of the face dual to each quad side."""
    other = np.array(OTHER_AXES)[axes]  # (E, 2)
    return other[:, _SIDE_AXIS_SLOT]


def _tube_sides(config, cell_ids, axes) -> np.ndarray:
    """(E, 4) bool: quad side i crosses a face whose inside corners both cells join (a tube)."""
    tube = np.zeros(cell_ids.shape, dtype=bool)
    # rare: only quads with a cell that joins some face's inside corners can have one
    maybe = np.flatnonzero(FACE_JOINED.any(axis=1)[config][cell_ids].any(axis=1))
    corner_config = config[cell_ids[maybe]]  # (M, 4)
    normal = _side_normals(axes[maybe])
    face_from = 2 * normal + _SIDE_FROM
    face_to = 2 * normal + 1 - _SIDE_FROM
    nxt = corner_config[:, [1, 2, 3, 0]]
    tube[maybe] = FACE_JOINED[corner_config, face_from] & FACE_JOINED[nxt, face_to]
    return tube


def _tube_vertices(tube_sides, quads, points, axes, inside, base: int):
    """The vertices of the tube faces' segments, one per (face, inside corner of the face).

    Numbered from ``base`` in order of (face normal, the face's high cell, inside corner), each
    at the midpoint of its inside corner and the face centre (the mean of its segment's two
    crossed-edge midpoints).

    Returns:
        extra: (T, 3) float64 positions; side_ids: (E, 4) int64 vertex of each quad side, -1
        where the side crosses no tube face.
    """
    side_ids = np.full(tube_sides.shape, -1, dtype=np.int64)
    quad, side = np.nonzero(tube_sides)
    if len(quad) == 0:
        return np.zeros((0, 3)), side_ids
    shape = np.array(inside.shape)
    normal = _side_normals(axes)[quad, side]
    high = quads[quad, _SIDE_HIGHER[side]]  # (T, 3) cell on the face's high side
    near, axis = points[quad], axes[quad]
    far = near + np.eye(3, dtype=np.int64)[axis]
    corner = np.where(inside[tuple(near.T)][:, None], near, far)  # the edge's inside end
    n_flat = int(np.prod(shape))
    key = (normal * n_flat + np.ravel_multi_index(high.T, shape)) * n_flat
    key += np.ravel_multi_index(corner.T, shape)
    _, first, inverse = np.unique(key, return_index=True, return_inverse=True)
    side_ids[quad, side] = base + inverse.reshape(-1)
    centre = high[first] + 0.5 - 0.5 * np.eye(3)[normal[first]]
    return (corner[first] + centre) / 2.0, side_ids


def _outward_flip(points, axes, inside) -> np.ndarray:
    """(E,) bool: the quad's inside end point is the far one (its surface faces -axis)."""
    far = points + np.eye(3, dtype=np.int64)[axes]
    return inside[tuple(far.T)] & ~inside[tuple(points.T)]


#: for a quad split along a-c (row 0) or b-d (row 1): quad side i -> (triangle 0/1, position of
#: the side's first vertex in that triangle)
_SIDE_IN_TRIANGLE = np.array([[[0, 0], [0, 1], [1, 1], [1, 2]],
                              [[0, 0], [1, 0], [1, 1], [0, 2]]])


def _split_tube_sides(faces, quad_ids, side_ids, vertices) -> np.ndarray:
    """Put each tube vertex into the triangle holding its quad side.

    Triangle (x, y, z) with the vertex t on side x -> y becomes (x, t, z) in place, and (t, y, z)
    is appended (in order of quad, then side). No triangle holds two tube sides (its two quad
    sides share a cell, and no cell joins the inside corners of two faces with a common edge).
    """
    quad, side = np.nonzero(side_ids >= 0)
    if len(quad) == 0:
        return faces
    a, b, c, d = quad_ids[quad].T
    use_ac = np.linalg.norm(vertices[a] - vertices[c], axis=1) <= np.linalg.norm(
        vertices[b] - vertices[d], axis=1)
    triangle, start = _SIDE_IN_TRIANGLE[(~use_ac).astype(np.int64), side].T
    row = 2 * quad + triangle
    rolled = faces[row][np.arange(len(row))[:, None], (start[:, None] + np.arange(3)) % 3]
    x, y, z = rolled.T
    t = side_ids[quad, side]
    faces = faces.copy()
    faces[row] = np.stack([x, t, z], axis=1)
    return np.concatenate([faces, np.stack([t, y, z], axis=1)])


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


def _compact_vertices(quads: np.ndarray, vertex_dx3, shape):
    """One vertex per used cell, numbered in C order of the cells.

    Returns:
        vertices: (V, 3) float64 = cell + clipped offset; quad_ids: (E, 4) int64.
    """
    if len(quads) == 0:
        return np.zeros((0, 3)), np.zeros((0, 4), dtype=np.int64)
    flat = np.ravel_multi_index(quads.reshape(-1, 3).T, shape)
    used, inverse = np.unique(flat, return_inverse=True)
    cells = np.stack(np.unravel_index(used, shape), axis=1)
    offsets = np.clip(_cell_offsets(vertex_dx3, used), 0.0, 1.0)
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
    """Merge coincident vertices and drop faces that collapse: vertices, faces and the (F,)
    bool mask of the faces kept."""
    if len(vertices) == 0:
        return vertices, faces, np.ones(len(faces), dtype=bool)
    keys = np.round(vertices, digits)
    unique, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)  # keep the original vertex order
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    faces = rank[inverse.reshape(-1)][faces]
    ok = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return vertices[first[order]], faces[ok], ok


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
    return _keep_faces(vertices, faces, large_component_faces(faces, len(vertices), min_faces))


def large_component_faces(faces: np.ndarray, n_vertices: int, min_faces: int) -> np.ndarray:
    """(F,) bool: the face's connected component has at least ``min_faces`` faces."""
    labels = face_components(faces, n_vertices)
    sizes = np.bincount(labels) if len(labels) else np.zeros(0, dtype=np.int64)
    return sizes[labels] >= min_faces


def _keep_faces(vertices, faces, kept):
    """The faces where ``kept`` (F,) is set and the vertices they use, renumbered in order."""
    faces = faces[kept]
    used = np.unique(faces)
    remap = np.full(len(vertices), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    return vertices[used], remap[faces]


def component_volumes(vertices: np.ndarray, faces: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """(K,) signed volume enclosed by each connected component (``labels`` per face)."""
    if len(faces) == 0:
        return np.zeros(0)
    triangles = vertices[faces]
    volume = np.einsum("ij,ij->i", triangles[:, 0],
                       np.cross(triangles[:, 1], triangles[:, 2])) / 6.0
    return np.bincount(labels, volume)


def restore_folded_components(vertices: np.ndarray, faces: np.ndarray,
                              reference: np.ndarray) -> tuple[np.ndarray, int]:
    """Give every component whose enclosed volume has the opposite sign to the ``reference``
    vertices' (the same faces, e.g. surface nets), or is flattened to nearly none of it, the
    reference's vertices.

    A closed surface's signed volume tells inside from out: a learned vertex set that turns a
    component inside out (isolated voxels of noise grids, whose vertices a network may fold
    through each other) would leave an inverted surface; surface nets never does (the random-
    and noise-grid property tests). A component squashed flat (a lone voxel whose upper and
    lower faces the network put on one plane: volume ~1e-16 against surface nets' 0.04) has no
    inside at all, so one holding less than ``tol.fold_volume`` of the reference's volume is
    restored too.

    Returns:
        (vertices, the number of components restored).
    """
    if len(faces) == 0:
        return vertices, 0
    labels = face_components(faces, len(vertices))
    volume = component_volumes(vertices, faces, labels)
    expected = component_volumes(reference, faces, labels)
    folded = (np.sign(volume) != np.sign(expected)) | (
        np.abs(volume) < tol.fold_volume * np.abs(expected))
    if not folded.any():
        return vertices, 0
    restore = np.zeros(len(vertices), dtype=bool)
    restore[faces[folded[labels]].reshape(-1)] = True
    out = vertices.copy()
    out[restore] = reference[restore]
    return out, int(folded.sum())
