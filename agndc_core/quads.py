"""Quad output: the triangles of a dual-contouring mesh joined back into quads where that is safe.

Dual contouring makes one quad per crossed lattice edge and splits it into two triangles along
its shorter diagonal (``contour.dual_contour``; ``face_quads=True`` reports the quad of each
triangle, and ``remesh`` keeps it as ``RemeshResult.face_quads``). ``quad_mesh`` joins the two
triangles of a quad again when

* the quad has exactly two triangles (a tube vertex splits one of them: three, kept apart),
  four distinct vertices, and the two triangles share their diagonal with opposite windings;
* it is planar: each triangle's far vertex lies within ``tol.quad_planar`` voxels of the other
  triangle's plane (measured in the grid's index space, so the tolerance is in voxels whatever
  the voxel size);
* it is strictly convex: every corner turns the same way as the quad's normal, so the quad is
  not folded, not a bow tie, and no corner is straight (a straight corner makes a triangle
  with a vertex on one side);
* with ``groups`` (e.g. a material per triangle), both triangles are in the same group.

Everything else stays triangles, as Blender's Voxel Remesh leaves what it cannot make a quad.
The triangle mesh itself (``RemeshResult.faces``) is not changed: quads are an extra view of the
same surface (same vertices; triangulating each quad along its diagonal gives the two original
triangles back). Marching cubes has no quads: its meshes come back as triangles only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .tolerances import tol


@dataclass
class QuadMesh:
    """A mesh as quads plus the triangles that were not joined.

    Attributes:
        quads: (Q, 4) int64 vertex indices, wound like the triangles (outward);
        triangles: (T, 3) int64 the remaining triangles, in their original order;
        quad_faces: (Q, 2) int64 the two triangles (rows of the source ``faces``) of each quad;
        triangle_faces: (T,) int64 the source row of each remaining triangle.
    """

    quads: np.ndarray
    triangles: np.ndarray
    quad_faces: np.ndarray
    triangle_faces: np.ndarray

    @property
    def polygon_count(self) -> int:
        return len(self.quads) + len(self.triangles)

    @property
    def quad_fraction(self) -> float:
        """Quads among all polygons (0 for an empty mesh)."""
        return len(self.quads) / self.polygon_count if self.polygon_count else 0.0

    def polygon_faces(self) -> np.ndarray:
        """(Q + T,) int64: a source triangle of each polygon, quads first (the order writers
        and Blender use), to carry per-triangle values such as materials over."""
        return np.concatenate([self.quad_faces[:, 0], self.triangle_faces])


def quad_mesh(result, *, tolerance: float = tol.quad_planar, groups=None) -> QuadMesh:
    """The quads of a ``RemeshResult``; a result without quads (marching cubes) gives none.

    Planarity is measured in the grid's index space (``grid.world_to_index``), so
    ``tolerance`` is in voxels. ``groups``: optional (F,) value per face; a quad joins only
    triangles with equal values.
    """
    faces = np.asarray(result.faces, dtype=np.int64).reshape(-1, 3)
    if result.face_quads is None:
        return _all_triangles(faces)
    vertices = np.asarray(result.vertices, dtype=np.float64)
    if result.grid is not None:
        # planarity and convexity are affine invariant; only the distance needs voxel units
        vertices = result.grid.world_to_index(vertices)
    return join_quads(vertices, faces, result.face_quads, tolerance=tolerance, groups=groups)


def join_quads(vertices_vx3: np.ndarray, faces_fx3: np.ndarray, face_quads_f: np.ndarray, *,
               tolerance: float = tol.quad_planar, groups=None) -> QuadMesh:
    """Join pairs of triangles with the same quad id into quads where that is safe.

    Args:
        vertices_vx3: (V, 3) float coordinates in which ``tolerance`` is measured;
        faces_fx3: (F, 3) int triangles; face_quads_f: (F,) int quad id per triangle (< 0:
            none); tolerance: the largest distance of a triangle's far vertex from the other
            triangle's plane; groups: optional (F,) values that must agree within a quad.

    Returns:
        QuadMesh.
    """
    faces = np.asarray(faces_fx3, dtype=np.int64).reshape(-1, 3)
    first, second = _quad_pairs(np.asarray(face_quads_f, dtype=np.int64).reshape(-1))
    quads, ok = _pair_quads(faces[first], faces[second])
    if groups is not None:
        groups = np.asarray(groups).reshape(-1)
        ok &= groups[first] == groups[second]
    ok[ok] = _planar_convex(np.asarray(vertices_vx3, dtype=np.float64)[quads[ok]], tolerance)
    joined = np.zeros(len(faces), dtype=bool)
    joined[first[ok]] = joined[second[ok]] = True
    rest = np.flatnonzero(~joined)
    return QuadMesh(quads[ok], faces[rest], np.stack([first[ok], second[ok]], axis=1), rest)


def triangulate(quads_qx4: np.ndarray) -> np.ndarray:
    """(2Q, 3) triangles of quads (a, b, c, d) along their diagonal b - d: (a, b, d) and
    (b, c, d), same winding. ``join_quads`` puts the shared diagonal there, so this gives the
    joined triangles back."""
    quads = np.asarray(quads_qx4, dtype=np.int64).reshape(-1, 4)
    return np.stack([quads[:, [0, 1, 3]], quads[:, [1, 2, 3]]], axis=1).reshape(-1, 3)


def polygon_triangles(polygons: QuadMesh) -> np.ndarray:
    """(2Q + T, 3): the quads triangulated, then the remaining triangles."""
    return np.concatenate([triangulate(polygons.quads), polygons.triangles])


def _all_triangles(faces: np.ndarray) -> QuadMesh:
    return QuadMesh(np.zeros((0, 4), dtype=np.int64), faces,
                    np.zeros((0, 2), dtype=np.int64), np.arange(len(faces), dtype=np.int64))


def _quad_pairs(face_quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(P,) first and second face of each quad id held by exactly two faces."""
    if len(face_quads) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    order = np.argsort(face_quads, kind="stable")
    ids = face_quads[order]
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])  # first of each run of one id
    counts = np.diff(np.r_[starts, len(ids)])
    pair = starts[(counts == 2) & (ids[starts] >= 0)]
    return order[pair], order[pair + 1]


def _pair_quads(tri_a: np.ndarray, tri_b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Quads of triangle pairs that share one edge with opposite windings.

    ``tri_a`` rotated to (p, u, v), with p not in ``tri_b``, and ``tri_b`` rotated to
    (q, v, u) give the quad (p, u, q, v): its diagonal u - v splits it back into the two.

    Args:
        tri_a, tri_b: (P, 3) int64.

    Returns:
        quads: (P, 4) int64; ok: (P,) bool, the pair shares exactly two vertices (so the quad
        has four distinct ones) and its shared edge runs in opposite directions.
    """
    only_a = ~(tri_a[:, :, None] == tri_b[:, None, :]).any(axis=2)  # (P, 3)
    only_b = ~(tri_b[:, :, None] == tri_a[:, None, :]).any(axis=2)
    distinct = ((tri_a[:, [0, 1, 2]] != tri_a[:, [1, 2, 0]]).all(axis=1)
                & (tri_b[:, [0, 1, 2]] != tri_b[:, [1, 2, 0]]).all(axis=1))
    ok = distinct & (only_a.sum(axis=1) == 1) & (only_b.sum(axis=1) == 1)
    rows = np.arange(len(tri_a))[:, None]
    rolled_a = tri_a[rows, (np.argmax(only_a, axis=1)[:, None] + np.arange(3)) % 3]
    rolled_b = tri_b[rows, (np.argmax(only_b, axis=1)[:, None] + np.arange(3)) % 3]
    ok &= (rolled_b[:, 1] == rolled_a[:, 2]) & (rolled_b[:, 2] == rolled_a[:, 1])
    quads = np.stack([rolled_a[:, 0], rolled_a[:, 1], rolled_b[:, 0], rolled_a[:, 2]], axis=1)
    return quads, ok


def _planar_convex(corners_px4x3: np.ndarray, tolerance: float) -> np.ndarray:
    """(P,) bool: quad (p, u, q, v) is planar within ``tolerance`` and strictly convex.

    Planar: q lies within ``tolerance`` of the plane of (p, u, v) and p within it of the plane
    of (q, v, u). Convex: the turn at every corner (cross product of the incoming and outgoing
    sides) points along the quad's normal by more than ``tol.quad_corner`` of the sides'
    lengths (sine of the turn), which rules out folds, bow ties and straight corners.
    """
    p, u, q, v = (corners_px4x3[:, k] for k in range(4))
    normal_a = np.cross(u - p, v - p)  # (P, 3) triangle (p, u, v)
    normal_b = np.cross(v - q, u - q)  # triangle (q, v, u)
    len_a = np.linalg.norm(normal_a, axis=1)
    len_b = np.linalg.norm(normal_b, axis=1)
    ok = (len_a > 0) & (len_b > 0)
    safe_a, safe_b = np.where(ok, len_a, 1.0), np.where(ok, len_b, 1.0)
    off_a = np.abs(np.einsum("ij,ij->i", q - p, normal_a)) / safe_a
    off_b = np.abs(np.einsum("ij,ij->i", p - q, normal_b)) / safe_b
    ok &= (off_a <= tolerance) & (off_b <= tolerance)
    normal = normal_a / safe_a[:, None] + normal_b / safe_b[:, None]  # (P, 3)
    sides = np.roll(corners_px4x3, -1, axis=1) - corners_px4x3  # (P, 4, 3) side k: k -> k + 1
    incoming = np.roll(sides, 1, axis=1)  # side into corner k
    turn = np.einsum("pkj,pj->pk", np.cross(incoming, sides), normal)  # (P, 4)
    scale = np.linalg.norm(incoming, axis=2) * np.linalg.norm(sides, axis=2)
    return ok & (turn > tol.quad_corner * np.linalg.norm(normal, axis=1)[:, None] * scale).all(
        axis=1)
