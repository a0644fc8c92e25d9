"""Label maps imported per label: one named, closed object per label, in world place."""

import importlib

import bpy
import numpy as np
import pytest

from agndc_core.labelmaps import LabelMap, remesh_labels
from agndc_core.meshcheck import topology_violations
from agndc_core.study.voxel_art import three_labels

pytestmark = pytest.mark.blender

#: anisotropic voxels and an origin, as a scanner's label map has
AFFINE = np.array([[0.9, 0.0, 0.0, -20.0],
                   [0.0, 1.1, 0.0, 5.0],
                   [0.0, 0.0, 1.3, 7.0],
                   [0.0, 0.0, 0.0, 1.0]])




def _save(tmp_path, kind: str):
    values = three_labels()
    if kind == "npy":
        path = tmp_path / "seg.npy"
        np.save(path, values)
        return path, LabelMap(values)
    import nibabel

    path = tmp_path / "seg.nii.gz"
    nibabel.save(nibabel.Nifti1Image(values, AFFINE), str(path))
    return path, LabelMap(values, nibabel.load(str(path)).affine)


def _world_mesh(addon, obj):
    vertices, faces = addon.mesh_io.mesh_arrays(obj.data)
    matrix = np.array(obj.matrix_world)
    return vertices @ matrix[:3, :3].T + matrix[:3, 3], faces


@pytest.mark.parametrize("kind", ["npy", "nii"])
def test_three_label_volume_gives_three_named_closed_objects(addon, tmp_path, kind):
    path, volume = _save(tmp_path, kind)
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="agndc", per_label=True,
                                          compare_mc=False) == {"FINISHED"}
    names = sorted(obj.name for obj in bpy.data.objects)
    assert names == ["seg_label-1_AGNDC", "seg_label-3_AGNDC", "seg_label-7_AGNDC"]
    expected = remesh_labels(volume, method="agndc")
    for label, result in expected.items():
        obj = bpy.data.objects[f"seg_label-{label}_AGNDC"]
        assert obj.get("agndc_label") == label
        vertices, faces = _world_mesh(addon, obj)
        assert all(v == 0 for v in topology_violations(vertices, faces).values())
        # the Python API's mesh, where the label sits in the volume's world space
        np.testing.assert_array_equal(faces, result.faces)
        np.testing.assert_allclose(vertices, result.vertices, rtol=1e-6, atol=1e-4)


def test_label_subset_gives_only_those_and_unknown_labels_fail(addon, tmp_path, capfd):
    path, _ = _save(tmp_path, "nii")
    grid = bpy.ops.import_mesh.agndc_grid
    assert grid(filepath=str(path), method="mc", per_label=True, labels="7, 1") == {"FINISHED"}
    assert sorted(obj.name for obj in bpy.data.objects) == ["seg_label-1_MC", "seg_label-7_MC"]
    assert grid(filepath=str(path), method="mc", per_label=True, labels="7") == {"FINISHED"}
    assert len(bpy.data.objects) == 2  # label 7 again: replaced, label 1 kept
    before = sorted(obj.name for obj in bpy.data.objects)
    with pytest.raises(RuntimeError, match="no label 2, 9; the labels present are 1, 3, 7"):
        grid(filepath=str(path), method="mc", per_label=True, labels="2,9,3")
    assert sorted(obj.name for obj in bpy.data.objects) == before


def test_label_map_imported_as_one_mask_warns(addon, tmp_path, capfd):
    path, _ = _save(tmp_path, "nii")
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="mc") == {"FINISHED"}
    assert "seg.nii.gz holds 3 labels (1, 3, 7): read as one mask, they are merged into one " \
           "solid; tick Per Label to import each label as its own object" \
           in capfd.readouterr().out
    assert [obj.name for obj in bpy.data.objects] == ["seg_MC"]
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="mc",
                                          per_label=True) == {"FINISHED"}
    assert "seg_MC" in bpy.data.objects  # the merged result is not one of the labels'
    assert "holds 3 labels" not in capfd.readouterr().out


def test_per_label_estimate_covers_every_label(addon, tmp_path, monkeypatch):
    path, volume = _save(tmp_path, "nii")
    remesh = addon.remesh
    jobs = remesh.grid_jobs([path], remesh.Settings(method="agndc", per_label=True))
    assert [job.name for job in jobs] == ["seg_label-1", "seg_label-3", "seg_label-7"]
    for job, label in zip(jobs, (1, 3, 7)):
        assert job.shape == volume.grid(label).shape and job.estimate > 0
    merged = remesh.grid_jobs([path], remesh.Settings(method="agndc"))
    assert merged[0].shape == volume.shape
    operators = importlib.import_module(f"{addon.module}.operators")
    monkeypatch.setattr(addon.core.plan, "CONFIRM_SECONDS", 0.0)
    message = operators.confirm_message(jobs)
    assert message.startswith("3 grids (seg_label-1 ") and "seg_label-7 " in message
    total = sum(job.estimate for job in jobs)
    assert operators.format_seconds(total) in message


def test_per_label_partial_failure_and_cancel_behave_like_any_import(addon, tmp_path):
    import threading

    path, _ = _save(tmp_path, "npy")
    remesh = addon.remesh
    settings = remesh.Settings(method="mc", compare_mc=False, per_label=True)
    jobs = remesh.grid_jobs([path], settings)
    cancel = threading.Event()
    cancel.set()
    with pytest.raises(addon.core.errors.CancelledError):
        remesh.compute_jobs(jobs, settings, cancel=cancel)
    assert len(bpy.data.objects) == 0
    jobs = remesh.grid_jobs([path], settings)
    jobs[1].grid.occupancy[:] = False  # label 3's grid made unusable: that label fails alone
    remesh.compute_jobs(jobs, settings)
    reports = remesh.apply_jobs(jobs, settings)
    level, text = remesh.summarize(reports)
    assert level == "WARNING" and text.startswith("2 remeshed, 1 failed: seg_label-3: ")
    assert sorted(obj.name for obj in bpy.data.objects) == ["seg_label-1_MC", "seg_label-7_MC"]


def test_import_dialog_shows_per_label_and_its_list_when_ticked(addon):
    from types import SimpleNamespace

    operators = importlib.import_module(f"{addon.module}.operators")
    rna = bpy.ops.import_mesh.agndc_grid.get_rna_type()
    assert rna.properties["per_label"].name == "Per Label"
    assert "1,3,7" in rna.properties["labels"].description

    class Layout:
        use_property_split = use_property_decorate = active = False

        def column(self):
            return self

        def prop(self, data, name):
            assert name in rna.properties, name
            shown.append(name)

    for ticked in (False, True):
        shown = []
        data = SimpleNamespace(method="agndc", vox_models="INDEX", per_label=ticked,
                               low_poly=False, low_poly_mode="ERROR")
        operators.draw_settings(Layout(), data, mesh=False)
        start = shown.index("per_label")
        assert (shown[start + 1] == "labels") == ticked and shown.count("labels") == ticked
