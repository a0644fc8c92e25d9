"""scripts/agndc_batch.py as a subprocess (the bpy module standing in for ``blender -b``)."""

import csv
import os
import subprocess
import sys

import numpy as np
import pytest

from agndc_core.gridio import load_mesh, save_mesh
from agndc_core.pipeline import remesh_mesh
from conftest import RELEASE_ZIP, ROOT
from helpers import cad_part

pytestmark = pytest.mark.blender

SCRIPT = ROOT / "scripts" / "agndc_batch.py"


def _batch(*args, tmp_path):
    # a fresh user folder finds the add-on in this checkout; a release zip is found installed
    env = dict(os.environ) if RELEASE_ZIP else dict(os.environ,
                                                    BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    return subprocess.run([sys.executable, str(SCRIPT), "--", *map(str, args)], env=env,
                          capture_output=True, text=True, timeout=300)


def _rows(folder):
    with open(folder / "agndc_batch.csv", newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


@pytest.fixture
def inputs(tmp_path):
    folder = tmp_path / "in"
    folder.mkdir()
    vertices, faces = cad_part()
    save_mesh(vertices, faces, folder / "part.obj")
    grid = np.zeros((20, 16, 12), dtype=bool)
    grid[4:16, 3:12, 2:10] = True
    np.save(folder / "block.npy", grid)
    return folder


def test_batch_folder(inputs, tmp_path):
    out = tmp_path / "out"
    result = _batch("--input", inputs, "--output", out, "--res", 32, "--method", "mc",
                    tmp_path=tmp_path)
    assert result.returncode == 0, result.stderr + result.stdout
    rows = _rows(out)
    assert {(r["input"].rsplit("/", 1)[-1], r["status"]) for r in rows} == {
        ("part.obj", "ok"), ("block.npy", "ok")}
    assert all(int(r["faces"]) > 100 and float(r["seconds"]) > 0 for r in rows)
    # the batch mesh is the Python API's mesh (obj text round trip: 6 significant digits)
    vertices, faces = load_mesh(inputs / "part.obj")
    expected = remesh_mesh(vertices, faces, resolution=32, method="mc")
    got_v, got_f = load_mesh(out / "part_MC.obj")
    assert len(got_f) == len(expected.faces)
    np.testing.assert_allclose(np.sort(got_v, axis=0), np.sort(expected.vertices, axis=0),
                               atol=1e-5)
    assert (out / "block_MC.obj").is_file()


def test_batch_failing_input_gives_nonzero_status(inputs, tmp_path):
    np.save(inputs / "empty.npy", np.zeros((8, 8, 8), dtype=bool))
    (inputs / "broken.binvox").write_bytes(b"not a binvox file")
    (inputs / "noise.stl").write_bytes(np.random.default_rng(12).bytes(3000))
    out = tmp_path / "out"
    result = _batch("--input", inputs, "--output", out, "--res", 24, "--method", "mc",
                    "--no-distance", tmp_path=tmp_path)
    assert result.returncode == 1
    assert "FAILED" in result.stderr and "empty.npy" in result.stderr
    rows = {r["input"].rsplit("/", 1)[-1]: r for r in _rows(out)}
    assert {name: r["status"] for name, r in rows.items()} == {
        "part.obj": "ok", "block.npy": "ok", "empty.npy": "failed", "broken.binvox": "failed",
        "noise.stl": "failed"}
    # random bytes are named as an unreadable file, not as a mesh "without faces"
    assert "cannot read" in rows["noise.stl"]["error"]
    assert "no faces" not in rows["noise.stl"]["error"]
    assert (out / "part_MC.obj").is_file()  # the good inputs are still done


def test_batch_single_file_and_bad_arguments(inputs, tmp_path):
    target = tmp_path / "single" / "result.ply"
    target.parent.mkdir()
    result = _batch("--input", inputs / "part.obj", "--output", target, "--res", 16,
                    "--method", "mc", tmp_path=tmp_path)
    assert result.returncode == 0, result.stderr
    assert target.is_file()
    assert _batch("--input", inputs, tmp_path=tmp_path).returncode == 2  # --output missing
    missing = _batch("--input", tmp_path / "nope", "--output", tmp_path / "o",
                     tmp_path=tmp_path)
    assert missing.returncode == 2 and "no such file" in missing.stderr


def test_batch_label_maps_per_label(tmp_path):
    """--per-label: one output per label of each label map, named <input>_label-<value>;
    --labels picks some; a label asked for that a file lacks fails that file, as in the
    add-on's Per Label import, with a message naming the labels it holds."""
    folder = tmp_path / "in"
    folder.mkdir()
    volume = np.zeros((24, 20, 16), dtype=np.uint8)
    volume[3:10, 3:16, 3:12] = 1
    volume[12:20, 4:14, 2:13] = 2
    volume[4:9, 4:9, 13:15] = 5
    np.save(folder / "seg.npy", volume)
    out = tmp_path / "out"
    result = _batch("--input", folder, "--output", out, "--method", "mc", "--per-label",
                    "--no-distance", tmp_path=tmp_path)
    assert result.returncode == 0, result.stderr + result.stdout
    assert sorted(p.name for p in out.glob("*.obj")) == [
        "seg_label-1_MC.obj", "seg_label-2_MC.obj", "seg_label-5_MC.obj"]
    assert all(r["status"] == "ok" for r in _rows(out))
    subset = _batch("--input", folder, "--output", tmp_path / "subset", "--method", "mc",
                    "--per-label", "--labels", "5,2", "--no-distance", tmp_path=tmp_path)
    assert subset.returncode == 0, subset.stderr
    assert sorted(p.name for p in (tmp_path / "subset").glob("*.obj")) == [
        "seg_label-2_MC.obj", "seg_label-5_MC.obj"]
    missing = _batch("--input", folder, "--output", tmp_path / "missing", "--method", "mc",
                     "--per-label", "--labels", "2,7", "--no-distance", tmp_path=tmp_path)
    assert missing.returncode == 1
    (row,) = _rows(tmp_path / "missing")
    assert row["status"] == "failed" and "7" in row["error"]
