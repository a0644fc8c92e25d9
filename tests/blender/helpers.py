"""Scene builders and snapshots shared by the Blender tests."""

import math

import bpy
import numpy as np


def cad_part(seed: int = 7) -> tuple[np.ndarray, np.ndarray]:
    """A generated CAD part: (V, 3) float64, (F, 3) int64, longest side 1, centred."""
    try:
        from agndc_core.study.shapes import cad_part
    except ImportError:  # before the shape generator existed: a plate with a hole, by boolean
        return _box_with_hole()
    return cad_part(seed)


def _box_with_hole():
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    box = bpy.context.object
    box.scale = (1.0, 0.6, 0.3)
    bpy.ops.mesh.primitive_cylinder_add(radius=0.15, depth=1.0, vertices=48)
    hole = bpy.context.object
    modifier = box.modifiers.new("hole", "BOOLEAN")
    modifier.operation, modifier.object = "DIFFERENCE", hole
    bpy.context.view_layer.objects.active = box
    bpy.ops.object.modifier_apply(modifier="hole")
    bpy.ops.object.transform_apply(scale=True)
    mesh = box.data
    mesh.calc_loop_triangles()
    vertices = np.array([v.co[:] for v in mesh.vertices])
    faces = np.array([t.vertices[:] for t in mesh.loop_triangles], dtype=np.int64)
    bpy.data.objects.remove(hole)
    bpy.data.objects.remove(box)
    return vertices, faces


def add_object(mesh_io, name, vertices, faces, *, transformed=True, select=True):
    """Link a new mesh object; ``transformed`` gives it a non-trivial world matrix."""
    obj = bpy.data.objects.new(name, mesh_io.new_mesh(name, vertices, faces))
    bpy.context.scene.collection.objects.link(obj)
    if transformed:
        obj.location = (0.5, -1.0, 2.0)
        obj.rotation_euler = (math.radians(25), math.radians(-10), math.radians(40))
        obj.scale = (2.0, 2.0, 2.0)
        bpy.context.view_layer.update()  # matrix_world
    material = bpy.data.materials.new(f"{name}_material")
    obj.data.materials.append(material)
    if select:
        obj.select_set(True)
        bpy.context.view_layer.objects.active = obj
    return obj


def object_state(obj) -> dict:
    """Everything the remesher must not change on a source object."""
    mesh = obj.data
    coords = np.zeros(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", coords)
    loops = np.zeros(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    return {
        "name": obj.name,
        "mesh": mesh.name,
        "matrix": np.array(obj.matrix_world),
        "coords": coords,
        "loops": loops,
        "polygons": len(mesh.polygons),
        "materials": [m.name if m else None for m in mesh.materials],
        "modifiers": [m.name for m in obj.modifiers],
        "collections": sorted(c.name for c in obj.users_collection),
    }


def assert_same_object_state(before: dict, after: dict) -> None:
    assert before.keys() == after.keys()
    for key in before:
        if isinstance(before[key], np.ndarray):
            np.testing.assert_array_equal(before[key], after[key], err_msg=key)
        else:
            assert before[key] == after[key], key


def scene_state() -> dict:
    """Datablock names and object placements: equal before and after a failed run."""
    return {
        "objects": sorted((o.name, tuple(map(tuple, o.matrix_world))) for o in bpy.data.objects),
        "meshes": sorted(m.name for m in bpy.data.meshes),
        "collections": sorted(c.name for c in bpy.data.collections),
        "materials": sorted(m.name for m in bpy.data.materials),
        "scene_children": sorted(c.name for c in bpy.context.scene.collection.children),
    }


def mesh_world_bounds(obj) -> tuple[np.ndarray, np.ndarray]:
    """(3,) min and max of an object's mesh vertices in world coordinates."""
    coords = np.zeros(len(obj.data.vertices) * 3, dtype=np.float32)
    obj.data.vertices.foreach_get("co", coords)
    matrix = np.array(obj.matrix_world)
    world = coords.reshape(-1, 3) @ matrix[:3, :3].T + matrix[:3, 3]
    return world.min(axis=0), world.max(axis=0)


def boxes_overlap(a, b) -> bool:
    """Do two (lo, hi) boxes overlap (more than touching)?"""
    return bool(np.all(a[0] < b[1] - 1e-6) and np.all(b[0] < a[1] - 1e-6))


def signed_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    triangles = vertices[faces]
    return float(np.einsum("ij,ij->i", triangles[:, 0],
                           np.cross(triangles[:, 1], triangles[:, 2])).sum() / 6.0)


def select_only(*objects) -> None:
    for obj in bpy.context.selected_objects:
        obj.select_set(False)
    for obj in objects:
        obj.select_set(True)
    bpy.context.view_layer.objects.active = objects[0] if objects else None


def vox_bytes(models) -> bytes:
    """A MagicaVoxel file built by hand: ``models`` is a list of (size (3,), xyz (N, 3))."""
    import struct

    def chunk(chunk_id, content, children=b""):
        return struct.pack("<4sii", chunk_id, len(content), len(children)) + content + children

    children = chunk(b"PACK", struct.pack("<i", len(models)))
    for size, xyz in models:
        xyz = np.asarray(xyz, dtype=np.int64).reshape(-1, 3)
        xyzi = np.concatenate([xyz, np.full((len(xyz), 1), 7)], axis=1)
        children += chunk(b"SIZE", struct.pack("<3i", *size))
        children += chunk(b"XYZI", struct.pack("<i", len(xyz)) + xyzi.astype(np.uint8).tobytes())
    return b"VOX " + struct.pack("<i", 150) + chunk(b"MAIN", b"", children)


def block_voxels(lo, hi) -> np.ndarray:
    """(N, 3) integer coordinates of the voxels of the block lo <= xyz < hi."""
    axes = [np.arange(a, b) for a, b in zip(lo, hi)]
    return np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
