"""The only place mesh data crosses between Blender and numpy: bulk ``foreach_get`` /
``foreach_set`` on contiguous, correctly typed buffers, no per-vertex Python."""

import bpy
import numpy as np


def read_mesh(obj) -> tuple[np.ndarray, np.ndarray]:
    """Triangulated copy of an object's mesh data in its own (local) coordinates.

    Modifiers are ignored, as in Blender's own Voxel Remesh. Nothing on ``obj`` is changed
    (``calc_loop_triangles`` only fills a runtime cache).

    Returns:
        vertices: (V, 3) float64; faces: (F, 3) int64 (F = 0 for a mesh without faces).
    """
    return mesh_arrays(obj.data)


def new_mesh(name: str, vertices: np.ndarray, faces: np.ndarray) -> "bpy.types.Mesh":
    """A new mesh datablock from (V, 3) float vertices and (F, 3) int triangles."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float32).reshape(-1, 3)
    faces = np.ascontiguousarray(faces, dtype=np.int32).reshape(-1, 3)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(vertices))
    mesh.vertices.foreach_set("co", vertices.ravel())
    mesh.loops.add(faces.size)
    mesh.loops.foreach_set("vertex_index", faces.ravel())
    mesh.polygons.add(len(faces))
    mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
    mesh.polygons.foreach_set("loop_total", np.full(len(faces), 3, dtype=np.int32))
    mesh.update(calc_edges=True)
    mesh.validate(verbose=False)
    return mesh


def mesh_arrays(mesh) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) float64 vertices and (F, 3) int64 triangles (n-gons triangulated) of a mesh."""
    coords = np.zeros(len(mesh.vertices) * 3, dtype=np.float32)  # (V*3,)
    mesh.vertices.foreach_get("co", coords)
    mesh.calc_loop_triangles()
    tris = np.zeros(len(mesh.loop_triangles) * 3, dtype=np.int32)  # (F*3,)
    mesh.loop_triangles.foreach_get("vertices", tris)
    return coords.reshape(-1, 3).astype(np.float64), tris.reshape(-1, 3).astype(np.int64)


def set_smooth(mesh, smooth: bool) -> None:
    """Flat or smooth shading for every face."""
    if smooth:
        mesh.shade_smooth()
    else:
        mesh.shade_flat()


def world_bounds(obj) -> tuple[np.ndarray, np.ndarray]:
    """(3,) min and max of the object's bounding box in world coordinates."""
    corners = np.array([tuple(c) for c in obj.bound_box], dtype=np.float64)  # (8, 3) local
    matrix = np.array(obj.matrix_world, dtype=np.float64)  # (4, 4)
    world = corners @ matrix[:3, :3].T + matrix[:3, 3]
    return world.min(axis=0), world.max(axis=0)
