"""Low Poly in Blender: the option decimates the result, keeps it closed and leaves the
comparison mesh and the default run as they were."""

import importlib

import bpy
import numpy as np
import pytest

from agndc_core.meshcheck import topology_violations
from agndc_core.metrics import evaluate
from agndc_core.pipeline import remesh_mesh
from helpers import add_object, cad_part

pytestmark = pytest.mark.blender

RES = 32


def _mesh(obj):
    mesh_io = importlib.import_module("bl_ext.user_default.agndc_remesher.mesh_io")
    return mesh_io.mesh_arrays(obj.data)


def _assert_closed(obj):
    vertices, faces = _mesh(obj)
    assert not any(topology_violations(vertices, faces).values())


def test_low_poly_is_off_by_default(addon):
    settings = bpy.context.scene.agndc
    assert settings.low_poly is False
    rna = bpy.ops.object.agndc_remesh.get_rna_type().properties
    assert rna["low_poly"].default is False and rna["low_poly"].is_skip_save


def test_low_poly_max_error_reduces_the_faces_and_stays_closed(addon):
    vertices, faces = cad_part()
    add_object(addon.mesh_io, "Part", vertices, faces)
    assert bpy.ops.object.agndc_remesh(resolution=RES, method="mc", compare_mc=True,
                                       low_poly=True, low_poly_mode="ERROR",
                                       max_error=0.5) == {"FINISHED"}
    full = remesh_mesh(vertices, faces, resolution=RES, method="mc")
    low = bpy.data.objects["Part_MC"]  # no comparison for MC itself: this one is decimated
    assert len(low.data.polygons) < len(full.faces) / 2
    _assert_closed(low)
    expected = remesh_mesh(vertices, faces, resolution=RES, method="mc", decimate_error=0.5)
    assert len(low.data.polygons) == len(expected.faces)


def test_low_poly_target_faces_from_the_sidebar(addon):
    vertices, faces = cad_part()
    add_object(addon.mesh_io, "Part", vertices, faces)
    settings = bpy.context.scene.agndc
    settings.size_mode, settings.resolution, settings.method = "RESOLUTION", RES, "sharp"
    settings.compare_mc = True
    settings.low_poly, settings.low_poly_mode, settings.target_faces = True, "FACES", 2500
    assert bpy.ops.object.agndc_remesh() == {"FINISHED"}
    low, compare = bpy.data.objects["Part_Sharp"], bpy.data.objects["Part_MC"]
    assert 2000 <= len(low.data.polygons) <= 2500
    _assert_closed(low)
    # the comparison mesh is the full marching-cubes mesh of the same grid
    full_mc = remesh_mesh(vertices, faces, resolution=RES, method="mc")
    assert len(compare.data.polygons) == len(full_mc.faces)
    assert evaluate(*_mesh(low), vertices, faces)["cd"] < 2e-4  # the part, not a blob


def test_low_poly_grid_import(addon, tmp_path):
    from agndc_core.voxelize import voxelize

    vertices, faces = cad_part()
    path = tmp_path / "part.npz"
    np.savez(path, occupancy=voxelize(vertices, faces, RES).occupancy)
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="mc", compare_mc=False,
                                          low_poly=True, low_poly_mode="FACES",
                                          target_faces=2300) == {"FINISHED"}
    result = bpy.data.objects["part_MC"]
    assert 0 < len(result.data.polygons) <= 2300
    _assert_closed(result)


def test_low_poly_in_the_batch_script(tmp_path):
    import os
    import subprocess
    import sys

    from agndc_core.gridio import load_mesh, save_mesh
    from conftest import RELEASE_ZIP, ROOT

    folder = tmp_path / "in"
    folder.mkdir()
    save_mesh(*cad_part(), folder / "part.obj")
    env = dict(os.environ) if RELEASE_ZIP else dict(os.environ,
                                                    BLENDER_USER_RESOURCES=str(tmp_path / "user"))
    out = tmp_path / "out"
    result = subprocess.run([sys.executable, str(ROOT / "scripts" / "agndc_batch.py"), "--",
                             "--input", str(folder), "--output", str(out), "--res", str(RES),
                             "--method", "mc", "--target-faces", "2300"],
                            env=env, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr + result.stdout
    vertices, faces = load_mesh(out / "part_MC.obj")
    assert 0 < len(faces) <= 2300
    assert not any(topology_violations(vertices, faces).values())
