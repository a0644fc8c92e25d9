"""Batch runs per label (``agndc batch --per-label [--labels]``): one output per label of each
label map, named as single runs name them, one batch.csv row each, a failing label reported on
its own row while the others are written, and resume label by label."""

import os
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

from agndc_core import batch, batch_job, labelmaps
from agndc_core.cli import main
from agndc_core.errors import AGNDCError
from agndc_core.gridio import load_mesh, save_mesh
from agndc_core.meshcheck import topology_violations
from agndc_core.study.voxel_art import three_labels

#: anisotropic voxels and an origin: the label meshes must land in world place
AFFINE = np.diag([0.9, 1.1, 1.3, 1.0])
AFFINE[:3, 3] = (-20.0, 5.0, 7.0)
#: the labels of each input file of the ``volumes`` folder
LABELS = {"seg.nii.gz": [1, 3, 7], "sub/two.npy": [1, 3]}


@pytest.fixture(scope="module")
def volumes(tmp_path_factory):
    """A NIfTI 3-label volume and, in a subfolder, an .npy label map without label 7."""
    folder = tmp_path_factory.mktemp("labels")
    (folder / "sub").mkdir()
    nib.save(nib.Nifti1Image(three_labels(), AFFINE), folder / "seg.nii.gz")
    values = three_labels()
    values[values == 7] = 0
    np.save(folder / "sub" / "two.npy", values)
    return folder


def batch_args(inputs, out, *extra):
    return ["batch", *map(str, inputs), "-o", str(out), "--method", "mc", "--no-progress",
            "--workers", "1", *extra]


def rows_by_output(rows, out) -> dict:
    return {Path(row["output"]).relative_to(out).as_posix(): row for row in rows}


def test_every_label_of_every_file_is_a_closed_mesh_named_as_single_runs_name_it(
        volumes, tmp_path):
    out = tmp_path / "out"
    assert main(batch_args([volumes], out, "--per-label", "--workers", "2")) == 0
    rows = rows_by_output(batch.read_rows(out / batch.CSV_NAME), out)
    expected = {f"{name.split('.')[0]}_label-{label}.ply": label
                for name, labels in LABELS.items() for label in labels}
    assert {name: int(row["label"]) for name, row in rows.items()} == expected
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*.ply")) == sorted(expected)
    single = tmp_path / "single" / "seg.ply"
    single.parent.mkdir()
    assert main(["remesh", str(volumes / "seg.nii.gz"), "-o", str(single), "--per-label",
                 "--method", "mc"]) == 0
    for name, row in rows.items():
        assert row["status"] == "ok" and row["error"] == "", row
        vertices, faces = load_mesh(out / name)
        assert int(row["faces"]) == len(faces) > 0
        assert all(v == 0 for v in topology_violations(vertices, faces).values()), name
        if "/" not in name:  # seg.nii.gz: byte for byte what `agndc remesh --per-label` wrote
            path = labelmaps.label_output_path(single, int(row["label"]))
            assert (out / name).read_bytes() == path.read_bytes()
    # the label's mesh lies on the label's voxels in world space (the NIfTI affine applied)
    vertices, _ = load_mesh(out / "seg_label-3.ply")
    voxels = np.argwhere(three_labels() == 3)
    lo, hi = (voxels.min(0) - 1) @ AFFINE[:3, :3].T, (voxels.max(0) + 1) @ AFFINE[:3, :3].T
    assert np.all(vertices >= lo + AFFINE[:3, 3] - 1e-6)
    assert np.all(vertices <= hi + AFFINE[:3, 3] + 1e-6)
    assert not (out / "seg.ply").exists()


def test_label_subset_and_a_label_missing_from_one_file(volumes, tmp_path, capsys):
    out = tmp_path / "out"
    assert main(batch_args([volumes], out, "--labels", "7,3")) == 1
    rows = batch.read_rows(out / batch.CSV_NAME)
    # input order, then the order the labels were asked in
    assert [(Path(r["output"]).relative_to(out).as_posix(), r["status"]) for r in rows] == [
        ("seg_label-7.ply", "ok"), ("seg_label-3.ply", "ok"),
        ("sub/two_label-7.ply", "failed"), ("sub/two_label-3.ply", "ok")]
    assert rows[2]["error"] == "two.npy: no label 7; the labels present are 1, 3"
    assert sorted(p.name for p in out.rglob("*.ply")) == ["seg_label-3.ply", "seg_label-7.ply",
                                                         "two_label-3.ply"]
    captured = capsys.readouterr()
    assert f"FAILED {volumes / 'sub' / 'two.npy'} label 7: two.npy: no label 7" in captured.err
    assert "3 done, 0 skipped (up to date), 1 failed" in captured.out


def test_a_failing_label_is_reported_and_the_others_are_written(volumes, tmp_path,
                                                                 monkeypatch):
    real = batch_job.remesh_label

    def fails_on_label_3(volume, label, options, **kwargs):
        if label == 3:
            raise AGNDCError(f"{volume.source} label 3: cannot be meshed")
        return real(volume, label, options, **kwargs)

    monkeypatch.setattr(batch_job, "remesh_label", fails_on_label_3)
    rows = batch.remesh_many([volumes / "seg.nii.gz"], tmp_path, method="mc", workers=1,
                             per_label=True)
    assert [(r["label"], r["status"]) for r in rows] == [(1, "ok"), (3, "failed"), (7, "ok")]
    assert rows[1]["error"] == "seg.nii.gz label 3: cannot be meshed"
    assert sorted(p.name for p in tmp_path.glob("*.ply")) == ["seg_label-1.ply",
                                                             "seg_label-7.ply"]
    assert batch.summary(rows) == {"ok": 2, "failed": 1, "skipped": 0}
    # a rerun does only the label that is missing, and keeps the others' numbers
    monkeypatch.setattr(batch_job, "remesh_label", real)
    again = batch.remesh_many([volumes / "seg.nii.gz"], tmp_path, method="mc", workers=1,
                              per_label=True)
    assert [r["status"] for r in again] == ["skipped", "ok", "skipped"]
    assert [r["faces"] for r in again[::2]] == [str(r["faces"]) for r in rows[::2]]
    assert (tmp_path / "seg_label-3.ply").is_file()


def test_resume_label_by_label(volumes, tmp_path):
    inputs = [volumes / "seg.nii.gz"]
    first = batch.remesh_many(inputs, tmp_path, method="mc", workers=1, labels="1,3")
    assert [r["status"] for r in first] == ["ok", "ok"]
    mtimes = {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("*.ply")}
    # labels known: the file is not even read again; every label: read, each label skipped
    for labels in ("1,3", None):
        again = batch.remesh_many(inputs, tmp_path, method="mc", workers=1, per_label=True,
                                  labels=labels)
        done = {int(r["label"]): r["status"] for r in again}
        assert done == ({1: "skipped", 3: "skipped"} if labels else
                        {1: "skipped", 3: "skipped", 7: "ok"})
        assert {r["label"]: r["grid"] for r in again if r["status"] == "skipped"} == \
            {r["label"]: r["grid"] for r in first}  # the numbers of the run that made them
    assert {p.name: p.stat().st_mtime_ns for p in tmp_path.glob("*.ply")
            if p.name in mtimes} == mtimes
    redone = batch.remesh_many(inputs, tmp_path, method="mc", workers=1, labels=[3],
                               overwrite=True)
    assert [(r["label"], r["status"]) for r in redone] == [(3, "ok")]
    os.utime(inputs[0])  # a newer input: every label is stale
    stale = batch.remesh_many(inputs, tmp_path, method="mc", workers=1, per_label=True)
    assert [r["status"] for r in stale] == ["ok", "ok", "ok"]


def test_files_that_are_not_label_maps_fail_alone_and_usage_errors(volumes, tmp_path, capsys):
    folder = tmp_path / "in"
    folder.mkdir()
    (folder / "seg.npy").write_bytes((volumes / "sub" / "two.npy").read_bytes())
    save_mesh(np.eye(3), np.array([[0, 1, 2]]), folder / "part.obj")
    (folder / "solid.binvox").write_bytes(b"#binvox 1\ndim 2 2 2\ntranslate 0 0 0\nscale 1\n"
                                          b"data\n\x01\x08")
    np.save(folder / "empty.npy", np.zeros((4, 4, 4), dtype=np.int16))
    rows = batch.remesh_many([folder], tmp_path / "out", method="mc", workers=1,
                             per_label=True)
    status = {Path(r["output"]).name: (r["label"], r["status"], r["error"]) for r in rows}
    assert status["seg_label-1.ply"] == (1, "ok", "")
    assert status["seg_label-3.ply"] == (3, "ok", "")
    assert status["part.ply"] == (
        "", "failed", "part.obj: --per-label reads a label map (.npy .npz .nii .nii.gz), not "
        "a mesh")
    assert status["solid.ply"][1] == "failed" and "hold one solid" in status["solid.ply"][2]
    assert status["empty.ply"] == ("", "failed", "empty.npy: no label to mesh (every voxel "
                                   "is 0 or negative)")
    for args, message in ((["--per-label", "--method", "sharp"], "contours a mesh's own"),
                          (["--labels", "1,x"], "labels are whole numbers")):
        assert main(["batch", str(folder), "-o", str(tmp_path / "bad"), "--no-progress",
                     *args]) == 2
        assert message in capsys.readouterr().err
    assert not (tmp_path / "bad").exists()  # refused before any work


@pytest.mark.slow
def test_dask_engine_per_label_equals_serial(volumes, tmp_path):
    pytest.importorskip("distributed")
    rows = batch.remesh_many([volumes], tmp_path / "dask", method="mc", workers=2,
                             engine="dask", labels="3,1")
    serial = batch.remesh_many([volumes], tmp_path / "serial", method="mc", workers=1,
                               labels="3,1")
    assert [(r["label"], r["status"]) for r in rows] == [(3, "ok"), (1, "ok")] * 2
    for row in serial:
        name = Path(row["output"]).relative_to(tmp_path / "serial")
        assert (tmp_path / "dask" / name).read_bytes() == Path(row["output"]).read_bytes()
