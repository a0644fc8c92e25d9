"""The installed extension inside Blender: operator, grid import, user errors, UI hooks."""

import importlib
import threading

import bpy
import numpy as np
import pytest

from agndc_core.gridio import load_grid
from agndc_core.metrics import evaluate
from agndc_core.pipeline import remesh, remesh_mesh
from conftest import WEIGHTS
from helpers import (
    add_object,
    assert_same_object_state,
    boxes_overlap,
    cad_part,
    mesh_world_bounds,
    object_state,
    scene_state,
)

pytestmark = pytest.mark.blender

RES = 64
needs_weights = pytest.mark.skipif(not WEIGHTS.is_file(),
                                   reason=f"AGNDC weights not shipped yet ({WEIGHTS.name})")


def _run(**options):
    return bpy.ops.object.agndc_remesh(**options)


def _assert_api_mesh(obj, source_obj, vertices, faces, *, method, resolution=RES):
    """The operator's object holds exactly the Python API's mesh, placed beside the source."""
    expected = remesh_mesh(vertices, faces, resolution=resolution, method=method)
    got_v, got_f = _mesh(obj)
    assert len(got_f) == len(expected.faces)
    np.testing.assert_array_equal(got_f, expected.faces)
    np.testing.assert_allclose(got_v, expected.vertices, rtol=0, atol=1e-5)
    rotation_and_scale = np.array(obj.matrix_world)[:3, :3]
    np.testing.assert_allclose(rotation_and_scale, np.array(source_obj.matrix_world)[:3, :3])


def _assert_beside(result, source):
    """Offset from the source along the source's own (rotated) X axis, boxes apart."""
    offset = np.array(result.matrix_world)[:3, 3] - np.array(source.matrix_world)[:3, 3]
    x_axis = np.array(source.matrix_world)[:3, 0]
    x_axis /= np.linalg.norm(x_axis)
    assert offset @ x_axis > 0
    np.testing.assert_allclose(offset, (offset @ x_axis) * x_axis, atol=1e-5)
    bpy.context.view_layer.update()
    assert not boxes_overlap(mesh_world_bounds(result), mesh_world_bounds(source))


def _mesh(obj):
    mesh_io = importlib.import_module("bl_ext.user_default.agndc_remesher.mesh_io")
    return mesh_io.mesh_arrays(obj.data)


def test_extension_registered(addon):
    assert hasattr(bpy.types, "VIEW3D_PT_agndc_remesh")
    assert bpy.ops.object.agndc_remesh.get_rna_type().name == "Remesh with AGNDC"
    assert bpy.ops.import_mesh.agndc_grid.get_rna_type() is not None
    for ui_type, draw in [("DATA_PT_remesh", "draw_data_remesh"),
                          ("VIEW3D_MT_object", "draw_object_menu"),
                          ("TOPBAR_MT_file_import", "draw_import_menu")]:
        hooks = getattr(bpy.types, ui_type)._dyn_ui_initialize()
        assert draw in {fn.__name__ for fn in hooks}, ui_type
    assert addon.core.core.__name__ == f"{addon.module}.agndc_core", "not the vendored core"
    assert bpy.context.scene.agndc.resolution == 64


def test_remesh_cad_part(addon):
    vertices, faces = cad_part()
    source = add_object(addon.mesh_io, "Part", vertices, faces)
    before = object_state(source)
    assert _run(resolution=RES, method="mc", compare_mc=True) == {"FINISHED"}
    assert_same_object_state(before, object_state(source))
    result = bpy.data.objects["Part_MC"]
    assert result.name in bpy.data.collections["AGNDC Results"].objects
    assert 2_000 < len(result.data.polygons) < 200_000
    assert result.data.materials[0] == source.data.materials[0]  # shared, not copied
    _assert_beside(result, source)
    _assert_api_mesh(result, source, vertices, faces, method="mc")
    cd = evaluate(*_mesh(result), vertices, faces)["cd"]
    assert cd < 5e-4  # the same grid, 1/64 of the part: close to the source


def test_scene_settings_used_when_not_given(addon):
    vertices, faces = cad_part()
    add_object(addon.mesh_io, "Part", vertices, faces)
    bpy.context.scene.agndc.size_mode = "RESOLUTION"
    bpy.context.scene.agndc.resolution = 24
    bpy.context.scene.agndc.method = "mc"
    bpy.context.scene.agndc.smooth = True
    assert _run() == {"FINISHED"}
    result = bpy.data.objects["Part_MC"]
    assert result.data.polygons[0].use_smooth
    _assert_api_mesh(result, bpy.data.objects["Part"], vertices, faces, method="mc",
                     resolution=24)


def test_a_later_call_follows_the_sidebar_not_the_last_call(addon):
    """The operator's settings are never remembered from its last call (SKIP_SAVE): the
    button always runs what the sidebar shows."""
    bpy.ops.mesh.primitive_cube_add()
    assert _run(method="mc", resolution=16) == {"FINISHED"}
    bpy.ops.object.select_all(action="DESELECT")
    bpy.data.objects["Cube"].select_set(True)
    bpy.context.scene.agndc.method = "sharp"
    bpy.context.scene.agndc.size_mode = "VOXEL_SIZE"
    bpy.context.scene.agndc.voxel_size = 0.5
    assert _run() == {"FINISHED"}
    result = bpy.data.objects["Cube_Sharp"]
    assert len(result.data.polygons) == 6 * 4 * 4 * 2  # 2 units at 0.5: 4 x 4 quads a side
    rna = bpy.ops.object.agndc_remesh.get_rna_type().properties
    assert all(rna[name].is_skip_save for name in ("method", "voxel_size", "resolution",
                                                   "size_mode", "output", "use_modifiers"))


def test_several_selected_objects(addon):
    vertices, faces = cad_part()
    add_object(addon.mesh_io, "A", vertices, faces)
    add_object(addon.mesh_io, "B", vertices * 0.5, faces, transformed=False)
    bpy.ops.object.empty_add()  # a non-mesh in the selection is skipped
    bpy.data.objects["A"].select_set(True)
    bpy.data.objects["B"].select_set(True)
    assert _run(resolution=16, method="mc") == {"FINISHED"}
    assert {"A_MC", "B_MC"} <= set(bpy.data.objects.keys())
    assert {o.name for o in bpy.context.selected_objects} == {"A_MC", "B_MC"}


@needs_weights
def test_agndc_closer_than_mc(addon):
    vertices, faces = cad_part()
    source = add_object(addon.mesh_io, "Part", vertices, faces)
    before = object_state(source)
    assert _run(resolution=RES, method="agndc", compare_mc=True) == {"FINISHED"}
    assert_same_object_state(before, object_state(source))
    agndc, mc = bpy.data.objects["Part_AGNDC"], bpy.data.objects["Part_MC"]
    assert len(agndc.data.polygons) > 1_000
    _assert_api_mesh(agndc, source, vertices, faces, method="agndc")
    cd_agndc = evaluate(*_mesh(agndc), vertices, faces)["cd"]
    cd_mc = evaluate(*_mesh(mc), vertices, faces)["cd"]
    assert cd_agndc < cd_mc


@needs_weights
def test_remesh_keeps_the_source_dimensions(addon):
    """docs/blender.md's promise: a slab comes back with its own bounding box (the faces that
    bound it are put on it); marching cubes of the same grid is off by a fraction of a voxel."""
    import trimesh

    box = trimesh.creation.box((1.0, 0.613, 0.377))
    add_object(addon.mesh_io, "Slab", box.vertices, box.faces)
    assert _run(resolution=24, method="agndc", compare_mc=True, threads=1) == {"FINISHED"}
    voxel = 1.0 / 22  # 24 voxels on the longest side, one empty voxel each end
    for name, kept in (("Slab_AGNDC", True), ("Slab_MC", False)):
        vertices, _ = _mesh(bpy.data.objects[name])  # the mesh in the source's own frame
        error = np.abs(np.stack([vertices.min(0), vertices.max(0)]) - box.bounds).max() / voxel
        assert error < 1e-4 if kept else error > 0.05, (name, error)


@pytest.fixture(scope="module")
def tiny_checkpoint(tmp_path_factory):
    """A checkpoint outside the extension (a copy of the shipped single-scale UNDC network under
    another name): the learned path through the Checkpoint preference, without torch."""
    import shutil

    from agndc_core.checkpoint import default_checkpoint_path

    folder = tmp_path_factory.mktemp("ckpt")
    source = default_checkpoint_path("undc")
    shutil.copy(source, folder / "tiny.safetensors")
    shutil.copy(source.with_suffix(".json"), folder / "tiny.json")
    return folder / "tiny.safetensors"


@pytest.fixture
def custom_checkpoint(addon):
    """Set the add-on preference for the duration of a test."""
    prefs = bpy.context.preferences.addons[addon.module].preferences

    def use(path):
        prefs.checkpoint = str(path)

    yield use
    prefs.checkpoint = ""


@pytest.mark.parametrize("normal_filter", [True, False])
def test_agndc_operator_equals_api(addon, tiny_checkpoint, custom_checkpoint, normal_filter):
    """The operator's mesh is the core's, with Denoise (the normal filter) on or off."""
    custom_checkpoint(tiny_checkpoint)
    vertices, faces = cad_part()
    source = add_object(addon.mesh_io, "Part", vertices, faces)
    before = object_state(source)
    # one thread: the result is the same with any count; a shared 2-core CI box is faster so
    assert _run(resolution=16, method="agndc", compare_mc=True, threads=1,
                normal_filter=normal_filter) == {"FINISHED"}
    assert_same_object_state(before, object_state(source))
    agndc, mc = bpy.data.objects["Part_AGNDC"], bpy.data.objects["Part_MC"]
    _assert_beside(agndc, source)
    _assert_beside(mc, agndc)  # the next free place along the source's X axis
    expected = remesh_mesh(vertices, faces, resolution=16, method="agndc",
                           checkpoint=tiny_checkpoint, threads=1, normal_filter=normal_filter)
    other = remesh_mesh(vertices, faces, resolution=16, method="agndc",
                        checkpoint=tiny_checkpoint, threads=1, normal_filter=not normal_filter)
    got_v, got_f = _mesh(agndc)
    np.testing.assert_array_equal(got_f, expected.faces)
    np.testing.assert_allclose(got_v, expected.vertices, rtol=0, atol=1e-5)
    assert np.abs(got_v - other.vertices).max() > 1e-3  # the switch made a difference


def test_import_grid_agndc_beside_mc(addon, tmp_path, tiny_checkpoint, custom_checkpoint):
    custom_checkpoint(tiny_checkpoint)
    path = _grid_file(tmp_path, "npz", resolution=16)
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="agndc", compare_mc=True,
                                          threads=1) == {"FINISHED"}
    agndc, mc = bpy.data.objects["part_AGNDC"], bpy.data.objects["part_MC"]
    np.testing.assert_allclose(np.array(agndc.matrix_world), np.eye(4))
    assert np.array(mc.matrix_world)[0, 3] > 0
    expected = remesh(load_grid(path), method="agndc", checkpoint=tiny_checkpoint, threads=1)
    np.testing.assert_array_equal(_mesh(agndc)[1], expected.faces)


@pytest.mark.skipif(WEIGHTS.is_file(), reason="the shipped weights exist")
def test_agndc_without_weights_reports_and_leaves_scene(addon):
    vertices, faces = cad_part()
    add_object(addon.mesh_io, "Part", vertices, faces)
    before = scene_state()
    with pytest.raises(RuntimeError, match="(?i)weights|checkpoint"):
        _run(resolution=16, method="agndc")
    assert scene_state() == before


@pytest.mark.parametrize("problem", ["missing", "corrupt"])
def test_bad_custom_checkpoint_reports_and_leaves_scene(addon, tmp_path, problem):
    """Missing: caught by the add-on up front; corrupt: the core's ModelError from the worker."""
    checkpoint = tmp_path / f"{problem}.safetensors"
    if problem == "corrupt":
        checkpoint.write_bytes(b"not safetensors")
    prefs = bpy.context.preferences.addons[addon.module].preferences
    prefs.checkpoint = str(checkpoint)
    try:
        vertices, faces = cad_part()
        add_object(addon.mesh_io, "Part", vertices, faces)
        before = scene_state()
        with pytest.raises(RuntimeError, match=f"{problem}.safetensors"):
            _run(resolution=16, method="agndc")
        assert scene_state() == before
    finally:
        prefs.checkpoint = ""


@pytest.mark.parametrize("case", ["nothing selected", "empty selected", "camera selected",
                                  "no faces", "voxel size too fine", "grid too large"])
def test_user_errors_leave_scene_untouched(addon, case):
    vertices, faces = cad_part()
    options = dict(resolution=RES, method="mc")
    if case == "nothing selected":
        add_object(addon.mesh_io, "Part", vertices, faces, select=False)
        message = "Select one or more mesh objects"
    elif case in ("empty selected", "camera selected"):
        add_object(addon.mesh_io, "Part", vertices, faces, select=False)
        bpy.ops.object.empty_add() if case == "empty selected" else bpy.ops.object.camera_add()
        message = "Select one or more mesh objects"
        assert not bpy.ops.object.agndc_remesh.poll()  # the button is disabled
    elif case == "no faces":
        add_object(addon.mesh_io, "Points", vertices, np.zeros((0, 3), dtype=np.int64))
        message = "Points: the mesh has no faces"
    elif case == "voxel size too fine":
        add_object(addon.mesh_io, "Part", vertices, faces)  # longest side 2 in the world
        options = dict(voxel_size=1e-4, method="mc")
        message = r"Part: a voxel size of 0\.0001 gives 20,002 voxels .*at least 0\.00[2-9]"
    else:
        bpy.ops.mesh.primitive_cube_add(size=2.0)  # 702 voxels a side: within 1024, but 702³
        options = dict(voxel_size=2 / 700, method="mc")
        message = ("Cube: a 702×702×702 grid has 345,948,408 voxels, more than the "
                   "216,000,000 the remesher handles; use a voxel size of at least")
    before = scene_state()
    with pytest.raises(RuntimeError, match=message):
        _run(**options)
    assert scene_state() == before


def test_property_limits_match_the_core(addon):
    """Hard limits: a value the core refuses cannot be typed (Blender clamps it)."""
    from agndc_core import plan

    for data in (bpy.context.scene.agndc,
                 bpy.ops.object.agndc_remesh.get_rna_type()):
        resolution = data.bl_rna.properties["resolution"]
        assert (resolution.hard_min, resolution.hard_max) == (plan.RESOLUTION_MIN,
                                                               plan.RESOLUTION_MAX)
        assert data.bl_rna.properties["voxel_size"].hard_min > 0
    settings = bpy.context.scene.agndc
    settings.resolution = 5000
    assert settings.resolution == plan.RESOLUTION_MAX == 1024  # as the CLI accepts
    settings.resolution = 1
    assert settings.resolution == plan.RESOLUTION_MIN


def _grid_file(tmp_path, kind: str, resolution: int = 40):
    vertices, faces = cad_part()
    from agndc_core.voxelize import voxelize

    occupancy = voxelize(vertices, faces, resolution).occupancy
    affine = np.diag([2.0, 2.0, 2.5, 1.0])  # e.g. millimetres
    affine[:3, 3] = (100.0, -50.0, 20.0)
    if kind == "npz":
        path = tmp_path / "part.npz"
        np.savez(path, occupancy=occupancy, affine=affine)
    else:
        import nibabel

        path = tmp_path / "part.nii.gz"
        nibabel.save(nibabel.Nifti1Image(occupancy.astype(np.uint8), affine), str(path))
    return path


@pytest.mark.parametrize("kind", ["npz", "nii.gz"])
def test_import_grid(addon, tmp_path, kind):
    path = _grid_file(tmp_path, kind)
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="mc") == {"FINISHED"}
    obj = bpy.data.objects["part_MC"]
    assert obj.name in bpy.data.collections["AGNDC Results"].objects
    np.testing.assert_allclose(np.array(obj.matrix_world), np.eye(4))  # world units kept
    expected = remesh(load_grid(path), method="mc")
    got_v, got_f = _mesh(obj)
    np.testing.assert_array_equal(got_f, expected.faces)
    np.testing.assert_allclose(got_v, expected.vertices, rtol=1e-6, atol=1e-4)
    assert got_v[:, 0].min() > 99.0 and got_v[:, 2].max() < 20.0 + 2.5 * 40  # in millimetres


def test_import_mirrored_nifti_faces_outward(addon, tmp_path):
    """A NIfTI whose affine mirrors space (det < 0, common for scanner data) still gives an
    outward-facing closed mesh in Blender: positive signed volume."""
    import nibabel

    occupancy = np.zeros((12, 10, 8), np.uint8)
    occupancy[2:10, 2:8, 2:6] = 1
    affine = np.diag([-1.5, 1.0, 2.0, 1.0])
    path = tmp_path / "mirrored.nii.gz"
    nibabel.save(nibabel.Nifti1Image(occupancy, affine), str(path))
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="mc") == {"FINISHED"}
    vertices, faces = _mesh(bpy.data.objects["mirrored_MC"])
    triangles = vertices[faces]
    volume = np.einsum("ij,ij->i", triangles[:, 0],
                       np.cross(triangles[:, 1], triangles[:, 2])).sum() / 6.0
    assert volume > 0.9 * 8 * 6 * 4 * 1.5 * 2.0  # the block's volume in world units, outward


@pytest.mark.parametrize("problem", ["empty", "unreadable", "missing", "not a grid"])
def test_import_grid_errors_leave_scene_untouched(addon, tmp_path, problem):
    path = tmp_path / {"not a grid": "part.txt"}.get(problem, "part.npy")
    if problem == "empty":
        np.save(path, np.zeros((16, 16, 16), dtype=bool))
    elif problem in ("unreadable", "not a grid"):
        path.write_bytes(b"this is not a grid")
    before = scene_state()
    with pytest.raises(RuntimeError, match="part"):
        bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="mc")
    assert scene_state() == before


def test_cancel_stops_before_the_scene_changes(addon):
    """What Esc does in the modal operator: the worker raises CancelledError, nothing is added."""
    remesh_mod = addon.remesh
    vertices, faces = cad_part()
    obj = add_object(addon.mesh_io, "Part", vertices, faces)
    settings = remesh_mod.Settings(resolution=32, method="mc")
    jobs = [remesh_mod.mesh_job(obj, settings)]
    before = scene_state()
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(addon.core.errors.CancelledError):
        remesh_mod.compute_jobs(jobs, settings, cancel=cancel)
    assert scene_state() == before


def test_progress_reaches_one(addon):
    remesh_mod = addon.remesh
    vertices, faces = cad_part()
    obj = add_object(addon.mesh_io, "Part", vertices, faces)
    seen = []
    report = remesh_mod.remesh_object(obj, remesh_mod.Settings(resolution=16, method="mc"),
                                      progress=lambda f, m: seen.append(f))
    assert seen and seen[-1] == 1.0 and all(0.0 <= f <= 1.0 for f in seen)
    assert "Part: MC" in report.summary() and "CD" in report.summary()
