"""Writers for meshes of quads and triangles (``quads.QuadMesh``): Wavefront OBJ and binary PLY.

trimesh writes triangles only, so polygon meshes are written here, with the precision of
trimesh's triangle files (8 decimals). Faces are written quads first, then triangles, wound
outward.
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
    """An ASCII PLY file with one ``vertex_indices`` list (4 or 3) per face.

    ASCII, not binary: readers that take a binary file's first list length for every face
    (trimesh's, and so ``gridio.load_mesh``) cannot read binary faces of mixed sizes.
    """
    vertices = np.asarray(vertices_vx3, dtype=np.float64).reshape(-1, 3)
    quads = np.asarray(quads_qx4, dtype=np.int64).reshape(-1, 4)
    triangles = np.asarray(triangles_tx3, dtype=np.int64).reshape(-1, 3)
    out = io.StringIO()
    out.write("ply\nformat ascii 1.0\ncomment AGNDC Remesher: quads and triangles\n"
              f"element vertex {len(vertices)}\nproperty float x\nproperty float y\n"
              f"property float z\nelement face {len(quads) + len(triangles)}\n"
              "property list uchar int vertex_indices\nend_header\n")
    np.savetxt(out, vertices, fmt="%.8f %.8f %.8f")
    np.savetxt(out, quads, fmt="4 %d %d %d %d")
    np.savetxt(out, triangles, fmt="3 %d %d %d")
    return out.getvalue().encode("ascii")
