"""The Quads option: Blender meshes of quads (and the triangles that stay), closed 2-manifolds
covering the same surface as the triangle result."""

import bmesh
import bpy
import numpy as np
import pytest

from agndc_core.pipeline import remesh
from conftest import WEIGHTS

pytestmark = pytest.mark.blender

needs_weights = pytest.mark.skipif(not WEIGHTS.is_file(),
                                   reason=f"AGNDC weights not shipped yet ({WEIGHTS.name})")


def face_sizes_and_manifold(obj) -> tuple[np.ndarray, bool]:
    """(P,) corners per face, and whether every edge joins exactly two faces with opposite
    directions (bmesh: ``is_contiguous``) and nothing was left to fix (``validate``)."""
    mesh = obj.data
    sizes = np.zeros(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("loop_total", sizes)
    bm = bmesh.new()
    try:
        bm.from_mesh(mesh)
        closed = all(len(edge.link_faces) == 2 and edge.is_contiguous for edge in bm.edges)
        closed &= all(vert.is_manifold for vert in bm.verts)
    finally:
        bm.free()
    return sizes, closed and not mesh.validate(verbose=False)


def triangle_count(obj) -> int:
    obj.data.calc_loop_triangles()
    return len(obj.data.loop_triangles)


@pytest.mark.parametrize("method, suffix", [("sharp", "Sharp"),
                                            pytest.param("agndc", "AGNDC",
                                                         marks=needs_weights)])
def test_quads_on_a_cube(addon, method, suffix):
    bpy.ops.mesh.primitive_cube_add()
    assert bpy.ops.object.agndc_remesh(method=method, resolution=24, quads=True,
                                       compare_mc=True) == {"FINISHED"}
    result = bpy.data.objects[f"Cube_{suffix}"]
    sizes, closed = face_sizes_and_manifold(result)
    assert closed
    assert np.count_nonzero(sizes == 4) >= 0.9 * len(sizes)
    assert set(np.unique(sizes)) <= {3, 4}
    # the same surface as without quads: twice the quads plus the triangles
    bpy.data.objects.remove(result)
    bpy.data.objects["Cube"].select_set(True)
    assert bpy.ops.object.agndc_remesh(method=method, resolution=24,
                                       compare_mc=False) == {"FINISHED"}
    triangles = bpy.data.objects[f"Cube_{suffix}"]
    assert len(triangles.data.polygons) == 2 * np.count_nonzero(sizes == 4) + np.count_nonzero(
        sizes == 3)
    # marching cubes, compared beside it, stays triangles
    mc_sizes, mc_closed = face_sizes_and_manifold(bpy.data.objects["Cube_MC"])
    assert mc_closed and set(np.unique(mc_sizes)) == {3}


def test_quads_keep_each_quad_in_one_material(addon):
    """Two material slots (the cube's +X side in the second): every face keeps one slot, and a
    quad joins only triangles of one slot (the core's ``groups``)."""
    bpy.ops.mesh.primitive_cube_add()
    cube = bpy.context.object
    cube.data.materials.append(bpy.data.materials.new("first"))
    cube.data.materials.append(bpy.data.materials.new("second"))
    normals = np.zeros(len(cube.data.polygons) * 3, dtype=np.float32)
    cube.data.polygons.foreach_get("normal", normals)
    slots = (normals.reshape(-1, 3)[:, 0] > 0.5).astype(np.int32)
    cube.data.polygons.foreach_set("material_index", slots)
    assert bpy.ops.object.agndc_remesh(method="sharp", resolution=24, quads=True,
                                       compare_mc=False) == {"FINISHED"}
    result = bpy.data.objects["Cube_Sharp"]
    sizes, closed = face_sizes_and_manifold(result)
    assert closed and np.count_nonzero(sizes == 4) >= 0.9 * len(sizes)
    material = np.zeros(len(sizes), dtype=np.int32)
    result.data.polygons.foreach_get("material_index", material)
    assert 0.1 < np.mean(material) < 0.25  # about one side of six


def test_quads_setting_in_the_sidebar(addon):
    assert bpy.context.scene.agndc.quads is False
    bpy.ops.mesh.primitive_cube_add()
    bpy.context.scene.agndc.quads = True
    assert bpy.ops.object.agndc_remesh(method="sharp", resolution=16,
                                       compare_mc=False) == {"FINISHED"}
    sizes, closed = face_sizes_and_manifold(bpy.data.objects["Cube_Sharp"])
    assert closed and np.all(sizes == 4)  # a cube at 16 voxels: flat faces, straight edges


@needs_weights
def test_import_grid_with_quads(addon, tmp_path):
    occupancy = np.zeros((24, 18, 14), bool)
    occupancy[2:22, 2:16, 2:12] = True
    path = tmp_path / "block.npy"
    np.save(path, occupancy)
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="agndc", quads=True,
                                          compare_mc=False) == {"FINISHED"}
    obj = bpy.data.objects["block_AGNDC"]
    sizes, closed = face_sizes_and_manifold(obj)
    assert closed and np.count_nonzero(sizes == 4) >= 0.9 * len(sizes)
    expected = remesh(occupancy, method="agndc")
    assert triangle_count(obj) == len(expected.faces)
