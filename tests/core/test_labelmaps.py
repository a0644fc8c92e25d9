"""Label maps meshed per label (agndc_core/labelmaps.py, ``agndc remesh --per-label``)."""

import threading
import warnings

import nibabel as nib
import numpy as np
import pytest

from agndc_core.cli import main
from agndc_core.errors import AGNDCError, CancelledError, GridError, GridFileError
from agndc_core.gridio import load_grid, load_mesh
from agndc_core.labelmaps import (
    LabelMap,
    MergedLabelsWarning,
    iter_remesh_labels,
    label_output_path,
    load_label_map,
    parse_labels,
    remesh_labels,
)
from agndc_core.meshcheck import topology_violations
from agndc_core.pipeline import remesh
from agndc_core.study.voxel_art import three_labels

#: anisotropic voxels, a shear and an origin: world placement is not the identity
AFFINE = np.array([[0.9, 0.0, 0.0, -20.0],
                   [0.0, 1.1, 0.2, 5.0],
                   [0.0, 0.0, 1.3, 7.0],
                   [0.0, 0.0, 0.0, 1.0]])




@pytest.fixture
def volume() -> LabelMap:
    return LabelMap(three_labels(), AFFINE, source="three.nii.gz")


def test_labels_are_the_positive_values_with_their_voxel_counts(volume):
    values = three_labels()
    counts = volume.labels()
    assert list(counts) == [1, 3, 7]
    assert counts == {label: int(np.count_nonzero(values == label)) for label in (1, 3, 7)}
    assert counts[3] == 10 * 12 * 24


def test_label_grid_is_cropped_and_keeps_its_voxels_world_positions(volume):
    values = three_labels()
    for label in (1, 3, 7):
        grid = volume.grid(label)
        whole = np.argwhere(values == label)
        assert grid.occupancy.sum() == len(whole)
        # the box plus CROP_MARGIN, clipped to the volume
        expected = np.minimum(whole.max(0) + 3, values.shape) - np.maximum(whole.min(0) - 2, 0)
        assert grid.shape == tuple(expected)
        cropped = grid.index_to_world(np.argwhere(grid.occupancy))
        np.testing.assert_allclose(cropped, whole @ AFFINE[:3, :3].T + AFFINE[:3, 3],
                                   atol=1e-12)
    full = volume.grid(3, crop=False)
    assert full.shape == values.shape
    np.testing.assert_array_equal(full.affine, AFFINE)


@pytest.mark.parametrize("method", ["mc", "surfacenets", "agndc"])
def test_cropped_label_meshes_equal_the_uncropped_ones(volume, method):
    """Why the crop is allowed: the same vertices (to float rounding) in the same order."""
    cropped = remesh_labels(volume, method=method)
    whole = remesh_labels(volume, method=method, crop=False)
    assert list(cropped) == list(whole) == [1, 3, 7]
    for label in cropped:
        np.testing.assert_array_equal(cropped[label].faces, whole[label].faces)
        np.testing.assert_allclose(cropped[label].vertices, whole[label].vertices,
                                   rtol=0, atol=1e-9)
        assert cropped[label].grid.shape != whole[label].grid.shape


def _signed_volume(vertices, faces) -> float:
    tri = vertices[faces]
    return float(np.einsum("ij,ij->i", tri[:, 0], np.cross(tri[:, 1], tri[:, 2])).sum() / 6)


@pytest.mark.parametrize("mirror", [False, True])
def test_every_label_is_a_closed_outward_mesh_where_the_label_is(mirror):
    affine = AFFINE @ np.diag([-1.0, 1, 1, 1]) if mirror else AFFINE  # NIfTI's usual flip
    values = three_labels()
    results = remesh_labels(LabelMap(values, affine), method="agndc")
    for label, result in results.items():
        assert all(v == 0 for v in topology_violations(result.vertices, result.faces).values())
        voxels = np.argwhere(values == label)
        lo, hi = voxels.min(0) - 1, voxels.max(0) + 1  # the surface lies within a voxel
        index = np.c_[result.vertices, np.ones(len(result.vertices))] @ np.linalg.inv(affine).T
        assert np.all(index[:, :3] >= lo - 1e-9) and np.all(index[:, :3] <= hi + 1e-9)
        world_voxels = len(voxels) * abs(np.linalg.det(affine[:3, :3]))
        assert 0.8 * world_voxels < _signed_volume(result.vertices, result.faces) \
            < 1.2 * world_voxels  # positive: wound outward in world space


def test_label_choice_and_labels_that_are_not_present(volume):
    assert volume.select(None) == [1, 3, 7]
    assert volume.select("7, 1 7") == [7, 1]
    assert list(remesh_labels(volume, labels=[7], method="mc")) == [7]
    with pytest.raises(AGNDCError, match=r"three.nii.gz: no label 2, 9; the labels present "
                                         r"are 1, 3, 7"):
        remesh_labels(volume, labels="3,2,9", method="mc")
    with pytest.raises(GridError, match="no label to mesh"):
        LabelMap(np.zeros((4, 4, 4), dtype=np.uint8)).select()
    with pytest.raises(AGNDCError, match="needs a mesh|mesh's own surface"):
        remesh_labels(volume, method="sharp")


def test_parse_labels():
    assert parse_labels("1,3,7") == [1, 3, 7]
    assert parse_labels(" 2  5,") == [2, 5]
    assert parse_labels("") is None and parse_labels(None) is None
    with pytest.raises(AGNDCError, match="whole numbers.*'x3'"):
        parse_labels("1,x3")


def test_values_that_are_not_labels():
    floats = three_labels().astype(np.float32)
    assert LabelMap(floats).labels() == LabelMap(three_labels()).labels()
    floats[5, 5, 5] = 0.4
    with pytest.raises(GridError, match="0.4 is not a whole number"):
        LabelMap(floats)
    with pytest.raises(GridError, match="3-D"):
        LabelMap(np.ones((4, 4), dtype=np.uint8))
    assert LabelMap(np.ones((2, 2, 2), dtype=bool)).labels() == {1: 8}


def test_label_maps_are_read_from_nifti_npy_and_npz(tmp_path):
    values = three_labels()
    nib.save(nib.Nifti1Image(values[..., None], AFFINE), tmp_path / "seg.nii.gz")
    np.save(tmp_path / "seg.npy", values)
    np.savez(tmp_path / "seg.npz", labels=values, voxel_size=np.array([0.5, 1.0, 2.0]),
             origin=np.array([1.0, 2.0, 3.0]))
    nifti = load_label_map(tmp_path / "seg.nii.gz")
    np.testing.assert_allclose(nifti.affine, AFFINE, rtol=1e-6)  # NIfTI stores float32
    np.testing.assert_array_equal(nifti.values, values)
    assert nifti.source == "seg.nii.gz"
    np.testing.assert_array_equal(load_label_map(tmp_path / "seg.npy").affine, np.eye(4))
    npz = load_label_map(tmp_path / "seg.npz")
    np.testing.assert_array_equal(npz.affine[:3, :3], np.diag([0.5, 1.0, 2.0]))
    np.testing.assert_array_equal(npz.affine[:3, 3], [1.0, 2.0, 3.0])
    for name in ("seg.nii.gz", "seg.npy", "seg.npz"):
        assert load_label_map(tmp_path / name).labels() == {1: 2109, 3: 2880, 7: 1684}
    (tmp_path / "x.binvox").write_bytes(b"#binvox 1\n")
    with pytest.raises(GridFileError, match="x.binvox: .binvox files hold one solid"):
        load_label_map(tmp_path / "x.binvox")


def test_a_label_map_read_as_one_mask_warns(tmp_path):
    nib.save(nib.Nifti1Image(three_labels(), AFFINE), tmp_path / "seg.nii.gz")
    with pytest.warns(MergedLabelsWarning, match=r"seg.nii.gz holds 3 labels \(1, 3, 7\): "
                                                 r"read as one mask, they are merged") as caught:
        grid = load_grid(tmp_path / "seg.nii.gz")
    assert caught[0].message.labels.tolist() == [1, 3, 7]
    np.testing.assert_array_equal(grid.occupancy, three_labels() > 0)
    mask = (three_labels() > 0).astype(np.uint8) * 255  # one value: a plain mask, no warning
    nib.save(nib.Nifti1Image(mask, AFFINE), tmp_path / "mask.nii.gz")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_grid(tmp_path / "mask.nii.gz")


def test_progress_covers_every_label_in_order(volume):
    seen = []
    remesh_labels(volume, method="mc", progress=lambda f, m: seen.append((f, m)))
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and fractions[-1] == pytest.approx(1.0)
    labels = [int(m.split(":")[0].split()[1]) for _, m in seen]
    assert labels == sorted(labels) and set(labels) == {1, 3, 7}
    ends = [f for f, m in seen if m.endswith("done")]
    assert len(ends) == 3 and 0.1 < ends[0] < ends[1] < 0.99  # each label its own share


def test_cancel_stops_between_and_inside_labels(volume):
    cancel = threading.Event()
    results = iter_remesh_labels(volume, method="mc", cancel=cancel)
    label, _ = next(results)
    assert label == 1
    cancel.set()
    with pytest.raises(CancelledError):
        next(results)
    with pytest.raises(CancelledError):  # set before: the first remesh stops at its start
        remesh_labels(volume, method="agndc", cancel=cancel)


def test_crop_is_off_when_the_network_sees_the_grid_as_given(volume):
    (result,) = remesh_labels(volume, labels=[3], method="mc", reframe=False).values()
    assert result.grid.shape == volume.shape


def test_cli_writes_one_file_per_label(tmp_path, capsys):
    nib.save(nib.Nifti1Image(three_labels(), AFFINE), tmp_path / "seg.nii.gz")
    out = tmp_path / "out" / "seg.obj"
    out.parent.mkdir()
    assert main(["remesh", str(tmp_path / "seg.nii.gz"), "-o", str(out), "--per-label",
                 "--method", "mc"]) == 0
    text = capsys.readouterr().out
    assert "seg.nii.gz: 3 labels, meshing 3" in text
    volume = load_label_map(tmp_path / "seg.nii.gz")
    for label in (1, 3, 7):
        path = label_output_path(out, label)
        assert path.name == f"seg_label-{label}.obj"
        assert f"{path}: label {label} ({volume.labels()[label]:,} voxels)" in text
        vertices, faces = load_mesh(path)
        expected = remesh(volume.grid(label), method="mc")
        np.testing.assert_allclose(vertices.min(0), expected.vertices.min(0), atol=1e-5)
        assert len(faces) == len(expected.faces)
    assert not out.exists()


def test_cli_label_subset_unknown_labels_and_the_merged_warning(tmp_path, capsys):
    np.save(tmp_path / "seg.npy", three_labels())
    nib.save(nib.Nifti1Image(three_labels(), AFFINE), tmp_path / "seg.nii.gz")
    out = tmp_path / "seg.ply"
    assert main(["remesh", str(tmp_path / "seg.npy"), "-o", str(out), "--labels", "3",
                 "--method", "mc"]) == 0
    assert sorted(p.name for p in tmp_path.glob("*.ply")) == ["seg_label-3.ply"]
    assert main(["remesh", str(tmp_path / "seg.npy"), "-o", str(out), "--labels", "3,4",
                 "--method", "mc"]) == 2
    assert "agndc: error: seg.npy: no label 4; the labels present are 1, 3, 7" \
        in capsys.readouterr().err
    (tmp_path / "part.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    assert main(["remesh", str(tmp_path / "part.obj"), "-o", str(out), "--per-label"]) == 2
    assert "part.obj: --per-label reads a label map" in capsys.readouterr().err
    assert main(["remesh", str(tmp_path / "seg.nii.gz"), "-o", str(out), "--method", "mc"]) == 0
    err = capsys.readouterr().err
    assert "agndc: warning: seg.nii.gz holds 3 labels (1, 3, 7): read as one mask, they are " \
           "merged into one solid; --per-label meshes each label on its own" in err


def test_npy_label_map_read_as_a_binary_grid_says_what_to_do(tmp_path):
    np.save(tmp_path / "seg.npy", three_labels())
    with pytest.raises(GridError, match=r"seg.npy: a label map \(3 labels: 1, 3, 7\), not a "
                                        r"binary grid: mesh each label on its own "
                                        r"\(agndc remesh --per-label; Blender: Per Label\)"):
        load_grid(tmp_path / "seg.npy")
    np.savez(tmp_path / "mask.npz", occupancy=(three_labels() == 3).astype(np.int16))
    assert load_grid(tmp_path / "mask.npz").occupancy.sum() == 2880  # one label: a mask
