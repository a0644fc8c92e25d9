"""The only place mesh data crosses between Blender and numpy: bulk ``foreach_get`` /
``foreach_set`` on contiguous, correctly typed buffers, no per-vertex Python."""

import bpy
import numpy as np

#: object types whose bounding boxes results must not land on
SOLID_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT", "VOLUME", "CURVES", "POINTCLOUD",
               "GPENCIL", "GREASEPENCIL"}


def read_mesh(obj, use_modifiers: bool = True, depsgraph=None):
    """Triangulated copy of an object's mesh in its own (local) coordinates.

    Args:
        use_modifiers: the evaluated mesh (modifiers applied, what the viewport shows); False:
            the base mesh, as Blender's own Voxel Remesh. Nothing on ``obj`` is changed.

    Returns:
        vertices: (V, 3) float64; faces: (F, 3) int64 (F = 0 for a mesh without faces);
        materials: (F,) int32 material slot of each triangle.
    """
    if not use_modifiers:
        return mesh_arrays(obj.data, materials=True)
    depsgraph = depsgraph or bpy.context.evaluated_depsgraph_get()
    evaluated = obj.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    try:
        return mesh_arrays(mesh, materials=True)
    finally:
        evaluated.to_mesh_clear()


def new_mesh(name: str, vertices: np.ndarray, faces: np.ndarray,
             materials: np.ndarray | None = None, polygons=None) -> "bpy.types.Mesh":
    """A new mesh datablock from (V, 3) float vertices and (F, 3) int triangles, with an optional
    (F,) material slot per triangle. ``polygons`` (``quads.QuadMesh`` of the same triangles):
    its quads, then its remaining triangles, become the faces instead."""
    vertices = np.ascontiguousarray(vertices, dtype=np.float32).reshape(-1, 3)
    corners, sizes = _polygon_corners(faces, polygons)  # (L,), (P,)
    if materials is not None and polygons is not None:
        materials = np.asarray(materials).reshape(-1)[polygons.polygon_faces()]
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(vertices))
    mesh.vertices.foreach_set("co", vertices.ravel())
    mesh.loops.add(corners.size)
    mesh.loops.foreach_set("vertex_index", corners)
    mesh.polygons.add(len(sizes))
    mesh.polygons.foreach_set("loop_start", (np.cumsum(sizes) - sizes).astype(np.int32))
    mesh.polygons.foreach_set("loop_total", sizes)
    if materials is not None and len(sizes):
        mesh.polygons.foreach_set("material_index",
                                  np.ascontiguousarray(materials, dtype=np.int32).reshape(-1))
    mesh.update(calc_edges=True)
    mesh.validate(verbose=False)
    return mesh


def color_material(name: str, rgba) -> "bpy.types.Material":
    """The material ``name``, created when missing with a Principled BSDF of base colour ``rgba``
    (4 floats, linear) and the same viewport colour (Solid shading); an existing one is reused
    as it is, so a material the user edited keeps the edits."""
    material = bpy.data.materials.get(name)
    if material is not None:
        return material
    material = bpy.data.materials.new(name)
    material.diffuse_color = rgba
    material.use_nodes = True
    shader = next((node for node in material.node_tree.nodes
                   if node.type == "BSDF_PRINCIPLED"), None)
    if shader is not None:
        shader.inputs["Base Color"].default_value = rgba
        shader.inputs["Roughness"].default_value = 1.0
    return material


def _polygon_corners(faces, polygons) -> tuple[np.ndarray, np.ndarray]:
    """(L,) int32 vertex of each face corner and (P,) int32 corners per face: the triangles, or
    the quads then the remaining triangles of ``polygons``."""
    if polygons is None:
        faces = np.ascontiguousarray(faces, dtype=np.int32).reshape(-1, 3)
        return faces.ravel(), np.full(len(faces), 3, dtype=np.int32)
    corners = np.concatenate([np.asarray(polygons.quads).ravel(),
                              np.asarray(polygons.triangles).ravel()]).astype(np.int32)
    sizes = np.repeat(np.array([4, 3], dtype=np.int32),
                      [len(polygons.quads), len(polygons.triangles)])
    return corners, sizes


def mesh_arrays(mesh, materials: bool = False):
    """(V, 3) float64 vertices and (F, 3) int64 triangles (n-gons triangulated) of a mesh, and
    with ``materials`` the (F,) int32 material slot of each triangle."""
    coords = np.zeros(len(mesh.vertices) * 3, dtype=np.float32)  # (V*3,)
    mesh.vertices.foreach_get("co", coords)
    mesh.calc_loop_triangles()
    tris = np.zeros(len(mesh.loop_triangles) * 3, dtype=np.int32)  # (F*3,)
    mesh.loop_triangles.foreach_get("vertices", tris)
    arrays = coords.reshape(-1, 3).astype(np.float64), tris.reshape(-1, 3).astype(np.int64)
    if not materials:
        return arrays
    slots = np.zeros(len(mesh.loop_triangles), dtype=np.int32)  # (F,)
    mesh.loop_triangles.foreach_get("material_index", slots)
    return (*arrays, slots)


def polygon_areas(mesh) -> np.ndarray:
    """(P, 3) float64: each polygon's unit normal times its area (local coordinates)."""
    normals = np.zeros(len(mesh.polygons) * 3, dtype=np.float32)
    mesh.polygons.foreach_get("normal", normals)
    areas = np.zeros(len(mesh.polygons), dtype=np.float32)
    mesh.polygons.foreach_get("area", areas)
    return normals.reshape(-1, 3).astype(np.float64) * areas[:, None]


def set_smooth(mesh, smooth: bool) -> None:
    """Flat or smooth shading for every face."""
    if smooth:
        mesh.shade_smooth()
    else:
        mesh.shade_flat()


def world_bounds(obj) -> tuple[np.ndarray, np.ndarray]:
    """(3,) min and max of the object's (evaluated) bounding box in world coordinates."""
    return box_bounds(local_box(obj), np.array(obj.matrix_world, dtype=np.float64))


def local_box(obj) -> np.ndarray:
    """(8, 3) corners of the object's bounding box in its local coordinates."""
    return np.array([tuple(c) for c in obj.bound_box], dtype=np.float64)


def box_bounds(corners: np.ndarray, matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(3,) min and max of (N, 3) local points under a (4, 4) matrix."""
    world = corners @ matrix[:3, :3].T + matrix[:3, 3]
    return world.min(axis=0), world.max(axis=0)


def solid_bounds(scene, exclude=()) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) min and max corners of the world bounding boxes of the scene's solid objects."""
    boxes = [world_bounds(obj) for obj in scene.objects
             if obj.type in SOLID_TYPES and obj.name not in exclude]
    if not boxes:
        return np.zeros((0, 3)), np.zeros((0, 3))
    return np.array([b[0] for b in boxes]), np.array([b[1] for b in boxes])
