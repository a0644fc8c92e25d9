"""Slow, obviously correct dual contouring, cell by cell: the reference ``dual_contour`` is tested
against (same vertex numbering, same faces). Never used on a hot path.

Unlike the fast path it does not read the 256-case tables: each cell's patches are found by
flood-filling the cell's own corners, and tube faces by looking at both cells' components.
"""

from __future__ import annotations

import itertools

import numpy as np

from .contour import OTHER_AXES, _check_parity

#: the quad of the edge at p along a uses cells p + db e_b + dc e_c in this order (faces +a)
QUAD_STEPS = ((-1, -1), (0, -1), (0, 0), (-1, 0))


def dual_contour_naive(vertex_dx3, edge_dx3, inside=None):
    """Loop version of ``contour.dual_contour`` (without the optional clean-ups)."""
    if inside is not None:
        _check_parity(edge_dx3, inside)
    quads = _quads(edge_dx3)  # [(p, axis, [4 cells])]
    if inside is None:
        return _contour_cells(quads, vertex_dx3)
    return _contour_patches(quads, vertex_dx3, np.asarray(inside, dtype=bool))


def _quads(edge_dx3):
    """Crossed edges with four neighbouring cells, by axis then C order of the point."""
    dims = edge_dx3.shape[:3]
    quads = []
    for axis in range(3):
        b, c = OTHER_AXES[axis]
        for p in itertools.product(*(range(n) for n in dims)):
            if not edge_dx3[p + (axis,)]:
                continue
            if p[b] < 1 or p[c] < 1 or p[b] > dims[b] - 2 or p[c] > dims[c] - 2:
                continue
            if p[axis] > dims[axis] - 2:
                continue
            cells = []
            for db, dc in QUAD_STEPS:
                cell = list(p)
                cell[b] += db
                cell[c] += dc
                cells.append(tuple(cell))
            quads.append((p, axis, cells))
    return quads


def _contour_cells(quads, vertex_dx3):
    """Without ``inside``: one vertex per used cell (C order), quads facing +axis."""
    cells = sorted({cell for _, _, quad in quads for cell in quad})
    index = {cell: n for n, cell in enumerate(cells)}
    vertices = [_place(cell, vertex_dx3[cell], None) for cell in cells]
    faces = []
    for _, _, quad in quads:
        faces += _split([index[cell] for cell in quad], vertices, [None] * 4)
    return _arrays(vertices, faces)


def _contour_patches(quads, vertex_dx3, inside):
    """With ``inside``: one vertex per (cell, patch), tube faces get a vertex per segment."""
    patches = {}  # cell -> {(point, axis) of a crossed cell edge: patch id}
    for _, _, quad in quads:
        for cell in quad:
            if cell not in patches:
                patches[cell] = _cell_patches(inside, cell)
    index = {}
    vertices = []
    for cell in sorted(patches):
        n_patches = max(patches[cell].values()) + 1
        for patch in range(n_patches):
            index[cell, patch] = len(vertices)
            vertices.append(_place(cell, vertex_dx3[cell], _shift(cell, patches[cell], patch)
                                   if n_patches > 1 else None))
    polygons = []  # per quad: 4 corner vertices, then the tube key of each side (or None)
    tube_keys = set()
    for p, axis, quad in quads:
        far = list(p)
        far[axis] += 1
        inner = tuple(far) if inside[tuple(far)] else p  # the edge's inside end point
        if inside[tuple(far)] and not inside[p]:
            quad = quad[::-1]  # face from inside to outside
        corners = [index[cell, patches[cell][p, axis]] for cell in quad]
        sides = []
        for i in range(4):
            key = _tube_key(inside, quad[i], quad[(i + 1) % 4], inner)
            sides.append(key)
            if key is not None:
                tube_keys.add(key)
        polygons.append((corners, sides))
    tube_index = {}
    for key in sorted(tube_keys):
        normal, high, corner = key
        centre = [high[d] + (0.0 if d == normal else 0.5) for d in range(3)]
        tube_index[key] = len(vertices)
        vertices.append([(corner[d] + centre[d]) / 2.0 for d in range(3)])
    faces, appended = [], []
    for corners, sides in polygons:
        ids = [None if key is None else tube_index[key] for key in sides]
        triangles = _split(corners, vertices, ids)
        # the quads' own triangles in quad order; the second halves of split ones at the end
        faces += [t for t in triangles if not t[3]]
        appended += [t for t in triangles if t[3]]
    faces = [t[:3] for t in faces] + [t[:3] for t in appended]
    return _arrays(vertices, faces)


def _cell_patches(inside, cell):
    """{(point, axis): patch} for the crossed edges of one cell, by flood fill of its corners.

    Inside corners connect along the 12 cube edges, outside corners also along the 12 face
    diagonals; a crossed edge's patch is (inside component, outside component), numbered in
    order of the cell's edges (by axis, then the other two axes' offsets 00, 01, 10, 11).
    """
    corners = [tuple(cell[d] + o[d] for d in range(3))
               for o in itertools.product((0, 1), repeat=3)]

    def neighbours(point, diagonals):
        out = []
        for other in corners:
            steps = sum(abs(point[d] - other[d]) for d in range(3))
            if steps == 1 or (diagonals and steps == 2):
                out.append(other)
        return out

    component = {}
    for start in corners:
        if start in component:
            continue
        state = inside[start]
        stack, component[start] = [start], start
        while stack:
            point = stack.pop()
            for other in neighbours(point, diagonals=not state):
                if inside[other] == state and other not in component:
                    component[other] = start
                    stack.append(other)
    patches, ids = {}, {}
    for axis in range(3):
        b, c = OTHER_AXES[axis]
        for db, dc in ((0, 0), (0, 1), (1, 0), (1, 1)):
            start = list(cell)
            start[b] += db
            start[c] += dc
            end = list(start)
            end[axis] += 1
            start, end = tuple(start), tuple(end)
            if inside[start] == inside[end]:
                continue
            inner, outer = (start, end) if inside[start] else (end, start)
            key = (component[inner], component[outer])
            patches.setdefault(key, len(patches))
            ids[start, axis] = patches[key]
    return ids


def _shift(cell, patches, patch):
    """The patch's surface-nets point minus the cell's surface-nets offset (as float32)."""
    def midpoint(point, axis):
        mid = [float(point[d] - cell[d]) for d in range(3)]
        mid[axis] += 0.5
        return mid

    everything = [midpoint(*edge) for edge in patches]
    own = [midpoint(*edge) for edge, p in patches.items() if p == patch]
    cell_mean = np.float32(np.mean(everything, axis=0)).astype(np.float64)
    return np.mean(own, axis=0) - cell_mean


def _place(cell, offset, shift):
    """cell + clip(offset [+ shift]) in float64."""
    offset = [float(x) for x in offset]
    if shift is not None:
        offset = [offset[d] + float(shift[d]) for d in range(3)]
    return [cell[d] + min(max(offset[d], 0.0), 1.0) for d in range(3)]


def _tube_key(inside, cell_a, cell_b, inner):
    """(normal, high cell, inner) when the face between two cells is a tube face, else None.

    A tube face is ambiguous (inside corners on one diagonal) and each of the two cells
    connects those two inside corners through its own corners along cube edges.
    """
    normal = next(d for d in range(3) if cell_a[d] != cell_b[d])
    high = max(cell_a, cell_b, key=lambda cell: cell[normal])
    others = [d for d in range(3) if d != normal]
    face = []
    for u, v in ((0, 0), (1, 0), (1, 1), (0, 1)):
        point = list(high)
        point[others[0]] += u
        point[others[1]] += v
        face.append(tuple(point))
    values = [bool(inside[point]) for point in face]
    if values not in ([True, False, True, False], [False, True, False, True]):
        return None
    first, second = [point for point, value in zip(face, values) if value]
    for cell in (cell_a, cell_b):
        if not _joined_inside(inside, cell, first, second):
            return None
    return (normal, high, tuple(inner))


def _joined_inside(inside, cell, first, second):
    """Whether two inside corners of a cell are connected along its inside cube edges."""
    corners = {tuple(cell[d] + o[d] for d in range(3))
               for o in itertools.product((0, 1), repeat=3)}
    seen, stack = {first}, [first]
    while stack:
        point = stack.pop()
        for d in range(3):
            for step in (-1, 1):
                other = list(point)
                other[d] += step
                other = tuple(other)
                if other in corners and other not in seen and inside[other]:
                    seen.add(other)
                    stack.append(other)
    return second in seen


def _split(corners, vertices, tubes):
    """Triangles of one quad along its shorter diagonal, tube vertices put into their sides.

    Returns a list of (x, y, z, appended): a triangle whose side x -> y holds tube vertex t
    becomes (x, t, z) in place and (t, y, z) appended after all quads' triangles.
    """
    a, b, c, d = corners
    pa, pb, pc, pd = (np.array(vertices[n]) for n in corners)
    if np.linalg.norm(pa - pc) <= np.linalg.norm(pb - pd):
        triangles = [[a, b, c], [a, c, d]]
    else:
        triangles = [[a, b, d], [b, c, d]]
    out = [tuple(t) + (False,) for t in triangles]
    appended = []
    for side in range(4):
        t = tubes[side]
        if t is None:
            continue
        x, y = corners[side], corners[(side + 1) % 4]
        for n, triangle in enumerate(triangles):
            for k in range(3):
                if triangle[k] == x and triangle[(k + 1) % 3] == y:
                    z = triangle[(k + 2) % 3]
                    out[n] = (x, t, z, False)
                    appended.append((t, y, z, True))
    return out + appended


def _arrays(vertices, faces):
    return (np.array(vertices, dtype=np.float64).reshape(-1, 3),
            np.array([list(f[:3]) for f in faces], dtype=np.int64).reshape(-1, 3))
