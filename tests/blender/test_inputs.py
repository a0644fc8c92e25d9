"""What is remeshed: each object on its own (partial failure), open meshes, the evaluated mesh
(modifiers), voxel size in world units, multi-model .vox files, several grid files, and the
sharp mode's flat faces and sharp edges."""

import itertools
import math

import bpy
import numpy as np
import pytest

from helpers import (
    assert_same_object_state,
    block_voxels,
    boxes_overlap,
    mesh_world_bounds,
    object_state,
    scene_state,
    select_only,
    signed_volume,
    vox_bytes,
)

pytestmark = pytest.mark.blender

OPEN_HINT = r"add thickness \(Solidify\) or close the holes"


def _arrays(addon, obj):
    return addon.mesh_io.mesh_arrays(obj.data)


def test_one_failure_does_not_throw_away_the_others(addon, capfd):
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.object
    bpy.ops.mesh.primitive_plane_add(size=2.0, location=(0.0, 5.0, 0.0))
    plane = bpy.context.object
    before = object_state(plane)
    select_only(cube, plane)
    assert bpy.ops.object.agndc_remesh(method="mc", resolution=24) == {"FINISHED"}
    assert "Cube_MC" in bpy.data.objects
    assert not any(name.startswith("Plane_") for name in bpy.data.objects.keys())
    assert_same_object_state(before, object_state(plane))
    out = capfd.readouterr().out
    assert "Warning: 1 remeshed, 1 failed: Plane: open surface with no inside to remesh: " \
           "add thickness (Solidify) or close the holes" in out


@pytest.mark.parametrize("shape", ["plane", "triangle"])
def test_open_surface_alone_says_what_to_do(addon, shape):
    if shape == "plane":
        bpy.ops.mesh.primitive_plane_add()
    else:
        mesh = addon.mesh_io.new_mesh("Tri", np.eye(3), np.array([[0, 1, 2]]))
        obj = bpy.data.objects.new("Tri", mesh)
        bpy.context.scene.collection.objects.link(obj)
        select_only(obj)
    before = scene_state()
    with pytest.raises(RuntimeError, match=f"open surface with no inside to remesh: {OPEN_HINT}"):
        bpy.ops.object.agndc_remesh(method="mc", resolution=24)
    assert scene_state() == before


def test_open_tube_is_remeshed_with_a_warning(addon, capfd):
    bpy.ops.mesh.primitive_cylinder_add(vertices=32, end_fill_type="NOTHING")
    assert bpy.ops.object.agndc_remesh(method="mc", resolution=24) == {"FINISHED"}
    assert "Cylinder_MC" in bpy.data.objects
    out = capfd.readouterr().out
    assert "Warning: 1 remeshed | Cylinder is not closed (64 open edges): remeshed as the " \
           "solid it encloses; add thickness (Solidify) or close the holes" in out


def _bevelled_cube(width=0.3, segments=1, rotate=False):
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.object
    if rotate:  # rotate the mesh itself, so its faces are oblique to the voxel grid
        cube.rotation_euler = (math.radians(20), math.radians(-35), math.radians(50))
        bpy.ops.object.transform_apply(rotation=True)
    bevel = cube.modifiers.new("Bevel", "BEVEL")
    bevel.width, bevel.segments = width, segments
    return cube


def test_modifiers_are_applied_unless_asked_not_to(addon):
    """A cube with an unapplied Bevel: remeshed as shown, or as its base mesh."""
    cube = _bevelled_cube(width=0.3, segments=3)
    evaluated = cube.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh()
    shown = signed_volume(*addon.mesh_io.mesh_arrays(evaluated))
    cube.evaluated_get(bpy.context.evaluated_depsgraph_get()).to_mesh_clear()
    assert shown < 7.9  # the bevel rounds off a visible share of the 8.0 of the base cube
    before = object_state(cube)
    assert bpy.ops.object.agndc_remesh(method="sharp", resolution=40) == {"FINISHED"}
    assert abs(signed_volume(*_arrays(addon, bpy.data.objects["Cube_Sharp"])) / shown - 1) < 2e-3
    select_only(cube)
    assert bpy.ops.object.agndc_remesh(method="mc", resolution=40,
                                       use_modifiers=False) == {"FINISHED"}
    base = signed_volume(*_arrays(addon, bpy.data.objects["Cube_MC"]))
    assert abs(base - 8.0) < 0.02  # MC of a box at 40³: the sharp base cube
    assert_same_object_state(before, object_state(cube))  # the modifier is still unapplied
    assert [m.name for m in cube.modifiers] == ["Bevel"]


def test_loose_vertices_do_not_change_the_grid(addon):
    """A vertex no face uses (left over from modelling) is not part of the solid: the grid is
    the one of the cube alone, and the remeshed cube keeps its size."""
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.object
    cube.data.vertices.add(1)
    cube.data.vertices[-1].co = (40.0, -3.0, 7.0)
    cube.data.update()
    settings = addon.remesh.Settings(method="mc", voxel_size=0.1, compare_mc=False)
    (job,) = addon.remesh.mesh_jobs([cube], settings)
    assert job.shape == (22, 22, 22)
    assert bpy.ops.object.agndc_remesh(method="mc", voxel_size=0.1) == {"FINISHED"}
    lo, hi = mesh_world_bounds(bpy.data.objects["Cube_MC"])
    assert np.allclose(hi - lo, 2.0, atol=0.1)


@pytest.mark.parametrize("scale", [(2.0, 2.0, 2.0), (1.0, 2.0, 0.5)])
def test_voxel_size_is_in_world_units(addon, scale):
    bpy.ops.mesh.primitive_cube_add(size=2.0)
    cube = bpy.context.object
    cube.scale = scale
    bpy.context.view_layer.update()
    settings = addon.remesh.Settings(method="mc", voxel_size=0.1, compare_mc=False)
    (job,) = addon.remesh.mesh_jobs([cube], settings)
    # the world box is 2 x scale: 0.1 voxels along each world side, + 1 empty voxel each way
    assert job.shape == tuple(int(round(2 * s / 0.1)) + 2 for s in scale)
    assert bpy.ops.object.agndc_remesh(method="mc", voxel_size=0.1) == {"FINISHED"}
    result = bpy.data.objects["Cube_MC"]
    vertices, faces = _arrays(addon, result)
    world = vertices @ np.array(result.matrix_world)[:3, :3].T
    edges = np.linalg.norm(world[faces[:, [1, 2, 0]]] - world[faces], axis=2).ravel()
    # marching cubes on flat faces: legs of one voxel, diagonals of sqrt(2): the world voxel
    assert abs(np.median(edges) - 0.1) < 0.01


def test_vox_with_several_models(addon, tmp_path, capfd):
    first = ((8, 8, 8), block_voxels((2, 2, 2), (6, 6, 6)))
    second = ((12, 6, 6), block_voxels((1, 1, 1), (11, 5, 5)))
    path = tmp_path / "two.vox"
    path.write_bytes(vox_bytes([first, second]))
    grid = bpy.ops.import_mesh.agndc_grid
    assert grid(filepath=str(path), method="mc") == {"FINISHED"}
    assert "holds 2 models; imported model 0 only" in capfd.readouterr().out
    v, _ = _arrays(addon, bpy.data.objects["two_model0_MC"])
    np.testing.assert_allclose(np.ptp(v, axis=0), 4.0, atol=0.6)  # model 0: the 4³ block
    assert grid(filepath=str(path), method="mc", model_index=1) == {"FINISHED"}
    v, _ = _arrays(addon, bpy.data.objects["two_model1_MC"])  # model 1: the 10 x 4 x 4 block
    assert np.ptp(v[:, 0]) > 2 * np.ptp(v[:, 1])
    with pytest.raises(RuntimeError, match="two: no model 5; the file holds 2"):
        grid(filepath=str(path), method="mc", model_index=5)
    count = len(bpy.data.objects)
    assert grid(filepath=str(path), method="mc", vox_models="ALL") == {"FINISHED"}
    assert len(bpy.data.objects) == count  # the same two models again: replaced
    objects = [bpy.data.objects[f"two_model{k}_MC"] for k in (0, 1)]
    bpy.context.view_layer.update()
    assert not boxes_overlap(mesh_world_bounds(objects[0]), mesh_world_bounds(objects[1]))


def test_several_grid_files_at_once(addon, tmp_path):
    """What a multi-file selection or a drag and drop of several files gives the importer."""
    block = np.zeros((10, 8, 6), bool)
    block[2:8, 2:6, 1:5] = True
    np.save(tmp_path / "a.npy", block)
    np.savez(tmp_path / "b.npz", occupancy=block[::-1])
    (tmp_path / "c.npy").write_bytes(b"not a grid")
    files = [{"name": name} for name in ("a.npy", "b.npz", "c.npy")]
    assert bpy.ops.import_mesh.agndc_grid(directory=str(tmp_path), files=files,
                                          method="mc") == {"FINISHED"}
    assert {"a_MC", "b_MC"} <= set(bpy.data.objects.keys())
    assert "c_MC" not in bpy.data.objects


def test_grid_import_has_no_sharp_mode(addon, tmp_path):
    np.save(tmp_path / "a.npy", np.ones((4, 4, 4), bool))
    bpy.context.scene.agndc.method = "sharp"  # the sidebar's choice, for meshes
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(tmp_path / "a.npy")) == {"FINISHED"}
    assert "a_AGNDC" in bpy.data.objects  # the grid importer's default instead
    with pytest.raises(TypeError):
        bpy.ops.import_mesh.agndc_grid(filepath=str(tmp_path / "a.npy"), method="sharp")


def _face_normals(vertices, faces):
    cross = np.cross(vertices[faces[:, 1]] - vertices[faces[:, 0]],
                     vertices[faces[:, 2]] - vertices[faces[:, 0]])
    area = np.linalg.norm(cross, axis=1)
    return cross / area[:, None], area / 2


def _edge_keys(faces, n_vertices):
    """(E,) unique int64 keys a * V + b (a < b) of the faces' edges."""
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    return np.unique(edges[:, 0] * n_vertices + edges[:, 1])


@pytest.mark.parametrize("method", ["sharp", "mc"])
def test_sharp_mode_keeps_a_bevelled_cube_flat_and_sharp(addon, method):
    """A chamfered cube (Bevel, 1 segment) turned off the grid: sharp mode's faces lie on the
    cube's 26 face directions, its big faces are planar and its creases are where the source's
    are; marching cubes of the same grid fails every one of these (kept as the control)."""
    cube = _bevelled_cube(width=0.3, segments=1, rotate=True)
    rotation = np.array(cube.matrix_world)[:3, :3]  # identity: the mesh itself was rotated
    np.testing.assert_allclose(rotation, np.eye(3), atol=1e-6)
    turn = np.array(bpy.data.objects["Cube"].data.polygons[0].normal)  # any face: off-axis
    assert np.abs(turn).max() < 0.99
    import mathutils

    frame = np.array(mathutils.Euler((math.radians(20), math.radians(-35),
                                      math.radians(50))).to_matrix())  # cube axes, in columns
    assert bpy.ops.object.agndc_remesh(method=method, resolution=48) == {"FINISHED"}
    suffix = {"sharp": "Sharp", "mc": "MC"}[method]
    vertices, faces = _arrays(addon, bpy.data.objects[f"Cube_{suffix}"])
    normals, area = _face_normals(vertices, faces)
    directions = np.array([d for d in itertools.product((-1, 0, 1), repeat=3) if any(d)], float)
    directions = (directions / np.linalg.norm(directions, axis=1, keepdims=True)) @ frame.T
    angle = np.degrees(np.arccos(np.clip((normals @ directions.T).max(axis=1), -1, 1)))
    on_directions = area[angle < 2].sum() / area.sum()
    top, chamfer = frame @ [0, 0, 1.0], frame @ (np.array([0, 1, 1.0]) / math.sqrt(2))
    on_top = normals @ top > math.cos(math.radians(2))
    on_chamfer = normals @ chamfer > math.cos(math.radians(2))
    keys = np.intersect1d(_edge_keys(faces[on_top], len(vertices)),
                          _edge_keys(faces[on_chamfer], len(vertices)))
    crease = np.stack([keys // len(vertices), keys % len(vertices)], axis=1)  # (E, 2)
    if method == "mc":
        assert on_directions < 0.1 and len(crease) == 0
        return
    assert on_directions > 0.75  # flat faces: most of the area on the 26 directions
    # the top face: one plane (top . x = 1), covering most of the source's 1.4 x 1.4 square
    plane_error = np.abs(vertices[np.unique(faces[on_top])] @ top - 1.0)
    assert plane_error.max() < 5e-3 and area[on_top].sum() > 0.8 * 1.4 ** 2
    # the top/chamfer crease: an edge chain on the source's crease line (y = 0.7, z = 1 in
    # the cube's frame) whose faces meet at the chamfer's 45 degrees
    assert len(crease) >= 10
    points = vertices[np.unique(crease)] @ frame
    assert np.abs(points[:, 2] - 1.0).max() < 5e-3 and np.abs(points[:, 1] - 0.7).max() < 5e-3
    assert np.ptp(points[:, 0]) > 1.2  # along most of the 1.4 long crease
