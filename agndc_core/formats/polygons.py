"""Writers for meshes of quads and triangles (``quads.QuadMesh``): Wavefront OBJ and binary PLY.

trimesh writes triangles only, so polygon meshes are written here, with the same layout as
trimesh's triangle files (OBJ: 8 decimals; PLY: binary little endian, float32 vertices, a
``uchar int`` list per face). Faces are written quads first, then triangles, outward wound.
"""

from __future__ import annotations

import io

import numpy as np


def obj_bytes(vertices_vx3: np.ndarray, quads_qx4: np.ndarray, triangles_tx3: np.ndarray) -> bytes:
    """An OBJ file: ``v x y z`` lines, then ``f a b c d`` and ``f a b c`` (1-based indices)."""
    out = io.StringIO()
    out.write("# AGNDC Remesher: quads and triangles\n")
    np.savetxt(out, np.asarray(vertices_vx3, dtype=np.float64).reshape(-1, 3),
               fmt="v %.8f %.8f %.8f")
    for polygons, size in ((quads_qx4, 4), (triangles_tx3, 3)):
        faces = np.asarray(polygons, dtype=np.int64).reshape(-1, size) + 1
        np.savetxt(out, faces, fmt="f" + " %d" * size)
    return out.getvalue().encode("utf-8")


def ply_bytes(vertices_vx3: np.ndarray, quads_qx4: np.ndarray, triangles_tx3: np.ndarray) -> bytes:
    """A binary little-endian PLY file with one ``vertex_indices`` list (3 or 4) per face."""
    vertices = np.asarray(vertices_vx3, dtype="<f4").reshape(-1, 3)
    blocks = [_face_records(quads_qx4, 4), _face_records(triangles_tx3, 3)]
    header = ("ply\nformat binary_little_endian 1.0\ncomment AGNDC Remesher\n"
              f"element vertex {len(vertices)}\nproperty float x\nproperty float y\n"
              f"property float z\nelement face {sum(len(b) for b in blocks)}\n"
              "property list uchar int vertex_indices\nend_header\n")
    return header.encode("ascii") + vertices.tobytes() + b"".join(b.tobytes() for b in blocks)


def _face_records(polygons: np.ndarray, size: int) -> np.ndarray:
    """(N,) packed records (count, size indices) of one polygon size."""
    faces = np.asarray(polygons, dtype=np.int64).reshape(-1, size)
    records = np.zeros(len(faces), dtype=[("count", "u1"), ("index", "<i4", (size,))])
    records["count"] = size
    records["index"] = faces
    return records
