"""Slow, obviously correct dual contouring, cell by cell: the reference ``dual_contour`` is tested
against (same vertex numbering, same faces). Never used on a hot path."""

from __future__ import annotations

import numpy as np

from .contour import OTHER_AXES


def dual_contour_naive(vertex_dx3, edge_dx3, inside=None):
    """Loop version of ``contour.dual_contour`` (without the optional clean-ups)."""
    dims = edge_dx3.shape[:3]
    quads = []
    for axis in range(3):
        b, c = OTHER_AXES[axis]
        for i in range(dims[0]):
            for j in range(dims[1]):
                for k in range(dims[2]):
                    if not edge_dx3[i, j, k, axis]:
                        continue
                    p = [i, j, k]
                    if p[b] < 1 or p[c] < 1 or p[b] > dims[b] - 2 or p[c] > dims[c] - 2:
                        continue
                    if p[axis] > dims[axis] - 2:
                        continue
                    quad = []
                    for db, dc in ((-1, -1), (0, -1), (0, 0), (-1, 0)):
                        cell = list(p)
                        cell[b] += db
                        cell[c] += dc
                        quad.append(tuple(cell))
                    if inside is not None:
                        far = list(p)
                        far[axis] += 1
                        if inside[tuple(far)] and not inside[tuple(p)]:
                            quad.reverse()
                    quads.append(quad)
    cells = sorted({cell for quad in quads for cell in quad})
    index = {cell: n for n, cell in enumerate(cells)}
    vertices = []
    for cell in cells:
        offset = [min(max(float(x), 0.0), 1.0) for x in vertex_dx3[cell]]
        vertices.append([cell[d] + offset[d] for d in range(3)])
    faces = []
    for quad in quads:
        a, b_, c_, d = (index[cell] for cell in quad)
        pa, pb, pc, pd = (np.array(vertices[n]) for n in (a, b_, c_, d))
        if np.linalg.norm(pa - pc) <= np.linalg.norm(pb - pd):
            faces += [[a, b_, c_], [a, c_, d]]
        else:
            faces += [[a, b_, d], [b_, c_, d]]
    return (np.array(vertices, dtype=np.float64).reshape(-1, 3),
            np.array(faces, dtype=np.int64).reshape(-1, 3))
