"""Where results go: beside their own source without landing on other objects, replacing the
results of an earlier run, keeping parent, transform and per-face materials, or replacing the
source (which is hidden, not deleted)."""

import math

import bpy
import numpy as np
import pytest

from helpers import (
    assert_same_object_state,
    boxes_overlap,
    mesh_world_bounds,
    object_state,
    select_only,
)

pytestmark = pytest.mark.blender


def _sphere_and_cube():
    """A sphere with a cube right where a naive "+X" result would go."""
    bpy.ops.mesh.primitive_uv_sphere_add(radius=1.0, location=(0.0, 0.0, 0.0))
    sphere = bpy.context.object
    bpy.ops.mesh.primitive_cube_add(size=2.0, location=(3.0, 0.0, 0.0))
    cube = bpy.context.object
    cube.rotation_euler = (0.0, 0.0, math.radians(30))  # results go along ITS x axis
    select_only(sphere, cube)
    return sphere, cube


def _boxes(names):
    bpy.context.view_layer.update()
    return {name: mesh_world_bounds(bpy.data.objects[name]) for name in names}


def test_several_objects_land_beside_their_own_source(addon):
    sphere, cube = _sphere_and_cube()
    assert bpy.ops.object.agndc_remesh(method="sharp", resolution=24, compare_mc=True) == \
        {"FINISHED"}
    made = ["Sphere_Sharp", "Sphere_MC", "Cube_Sharp", "Cube_MC"]
    boxes = _boxes(made + ["Sphere", "Cube"])
    for a in boxes:
        for b in boxes:
            if a < b:
                assert not boxes_overlap(boxes[a], boxes[b]), (a, b)
    for source in (sphere, cube):
        x_axis = np.array(source.matrix_world)[:3, 0] / np.linalg.norm(source.matrix_world.col[0])
        for suffix in ("Sharp", "MC"):
            result = bpy.data.objects[f"{source.name}_{suffix}"]
            offset = np.array(result.matrix_world.translation - source.matrix_world.translation)
            assert offset @ x_axis > 0  # along the source's own X axis, never back onto it
            np.testing.assert_allclose(offset, (offset @ x_axis) * x_axis, atol=1e-5)
            np.testing.assert_allclose(np.array(result.matrix_world)[:3, :3],
                                       np.array(source.matrix_world)[:3, :3], atol=1e-6)


def test_a_repeated_run_replaces_its_previous_results(addon):
    sphere, cube = _sphere_and_cube()
    options = dict(method="mc", resolution=20)
    assert bpy.ops.object.agndc_remesh(**options) == {"FINISHED"}
    first = {name: np.array(bpy.data.objects[name].matrix_world)
             for name in ("Sphere_MC", "Cube_MC")}
    count = len(bpy.data.objects)
    select_only(sphere, cube)
    assert bpy.ops.object.agndc_remesh(**options) == {"FINISHED"}
    assert len(bpy.data.objects) == count  # replaced, no "Cube_MC.001" on top of "Cube_MC"
    for name, matrix in first.items():
        np.testing.assert_allclose(np.array(bpy.data.objects[name].matrix_world), matrix)
    assert not any(mesh.users == 0 for mesh in bpy.data.meshes)  # old meshes removed too
    # another method is not a replacement: it goes to the next free place
    select_only(sphere)
    assert bpy.ops.object.agndc_remesh(method="sharp", resolution=20) == {"FINISHED"}
    boxes = _boxes(["Sphere", "Sphere_MC", "Sphere_Sharp", "Cube", "Cube_MC"])
    assert not any(boxes_overlap(boxes["Sphere_Sharp"], box)
                   for name, box in boxes.items() if name != "Sphere_Sharp")


def _parented_two_material_cube():
    """A cube under a rotated, scaled parent; its +Z face carries a second material."""
    bpy.ops.object.empty_add(location=(1.0, 2.0, 3.0), rotation=(0.3, -0.2, 0.5))
    parent = bpy.context.object
    parent.scale = (1.5, 1.5, 1.5)
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.object
    cube.location, cube.rotation_euler = (0.5, -0.5, 0.2), (0.1, 0.2, -0.4)
    cube.parent = parent
    red, blue = bpy.data.materials.new("red"), bpy.data.materials.new("blue")
    cube.data.materials.append(red)
    cube.data.materials.append(blue)
    normals = np.zeros(len(cube.data.polygons) * 3, dtype=np.float32)
    cube.data.polygons.foreach_get("normal", normals)
    slots = (normals.reshape(-1, 3)[:, 2] > 0.9).astype(np.int32)  # +Z face: blue
    cube.data.polygons.foreach_set("material_index", slots)
    cube.data.update()
    select_only(cube)
    bpy.context.view_layer.update()
    return parent, cube


def test_parent_transform_and_per_face_materials_are_kept(addon):
    parent, cube = _parented_two_material_cube()
    before = object_state(cube)
    assert bpy.ops.object.agndc_remesh(method="sharp", resolution=24) == {"FINISHED"}
    assert_same_object_state(before, object_state(cube))
    result = bpy.data.objects["Cube_Sharp"]
    assert result.parent == parent
    np.testing.assert_allclose(np.array(result.matrix_parent_inverse),
                               np.array(cube.matrix_parent_inverse), atol=1e-6)
    np.testing.assert_allclose(np.array(result.matrix_world)[:3, :3],
                               np.array(cube.matrix_world)[:3, :3], atol=1e-5)
    assert [m.name for m in result.data.materials] == ["red", "blue"]  # shared, not copied
    mesh = result.data
    centres = np.zeros(len(mesh.polygons) * 3, dtype=np.float32)
    mesh.polygons.foreach_get("center", centres)
    slots = np.zeros(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("material_index", slots)
    z = centres.reshape(-1, 3)[:, 2]  # local: the +Z face is at z = 1
    assert np.all(slots[z > 1 - 1e-4] == 1) and np.count_nonzero(z > 1 - 1e-4) > 100
    assert np.all(slots[z < 0.9] == 0)


def test_replace_source_hides_it_and_keeps_everything_else(addon):
    parent, cube = _parented_two_material_cube()
    cube_collection = bpy.data.collections.new("Parts")
    bpy.context.scene.collection.children.link(cube_collection)
    cube_collection.objects.link(cube)
    bpy.context.scene.collection.objects.unlink(cube)
    before = object_state(cube)
    options = dict(method="sharp", resolution=24, output="REPLACE", compare_mc=True)
    assert bpy.ops.object.agndc_remesh(**options) == {"FINISHED"}
    result = bpy.data.objects["Cube_Sharp"]
    assert "Cube_MC" not in bpy.data.objects  # replace makes the result only
    np.testing.assert_allclose(np.array(result.matrix_world), np.array(cube.matrix_world),
                               atol=1e-6)  # in the source's place
    assert result.parent == parent
    assert [c.name for c in result.users_collection] == ["Parts"]
    # the source is hidden (viewport and render), not deleted or changed: Ctrl Z (memfile
    # undo, which needs a window and is not available to the bpy module) restores the scene
    # before the operator, one step, since bl_options has UNDO
    assert cube.hide_get() and cube.hide_render
    assert_same_object_state(before, object_state(cube))
    assert "UNDO" in bpy.ops.object.agndc_remesh.bl_options
    assert bpy.context.view_layer.objects.active == result
    # running again from the (hidden) source replaces its result once more
    settings = addon.remesh.Settings(method="sharp", resolution=24, replace_source=True)
    addon.remesh.remesh_object(cube, settings)
    assert sorted(o.name for o in bpy.data.objects) == ["Cube", "Cube_Sharp", "Empty"]
    assert cube.hide_get()
