"""Outward faces in world coordinates for every affine, mirrored ones included."""

import numpy as np
import pytest
import trimesh

from agndc_core.checkpoint import default_checkpoint_path
from agndc_core.cli import main
from agndc_core.grid import VoxelGrid
from agndc_core.gridio import load_grid, save_grid
from agndc_core.pipeline import CHECKPOINT_NAMES, orient_to_affine, remesh
from conftest import edge_use_counts


def translated(linear, translation=(0.0, 0.0, 0.0)):
    affine = np.eye(4)
    affine[:3, :3] = np.diag(linear)
    affine[:3, 3] = translation
    return affine


AFFINES = {
    "identity": np.eye(4),
    "mirror x": translated((-1.0, 1.0, 1.0)),
    "mirror y, scaled, moved": translated((1.0, -2.0, 1.0), (3.0, -1.5, 10.0)),
}


def _learned(method):
    """A pytest param that skips when the shipped weights of ``method`` are missing."""
    present = default_checkpoint_path(CHECKPOINT_NAMES[method]).is_file()
    return pytest.param(method, marks=pytest.mark.skipif(not present,
                                                         reason=f"no shipped {method} weights"))


METHODS = ["mc", "mc_taubin", "surfacenets", _learned("undc"), _learned("agndc")]


def l_solid():
    """An L-shaped solid (not symmetric under any mirror of the axes) in a small grid."""
    occupancy = np.zeros((12, 10, 9), dtype=bool)
    occupancy[2:9, 2:5, 2:7] = True
    occupancy[2:5, 5:8, 2:7] = True
    return occupancy


def signed_volume(vertices, faces):
    return trimesh.Trimesh(vertices, faces, process=False).volume


@pytest.mark.parametrize("method", METHODS)
def test_every_affine_gives_a_positive_volume(method):
    occupancy = l_solid()
    volumes = {}
    for name, affine in AFFINES.items():
        result = remesh(VoxelGrid(occupancy, affine), method=method)
        assert np.all(edge_use_counts(result.faces) == 2), name
        volumes[name] = signed_volume(result.vertices, result.faces)
        assert volumes[name] > 0, f"{method}, {name}: inside out"
    # the same index-space mesh, scaled by |det|
    for name, affine in AFFINES.items():
        det = abs(np.linalg.det(affine[:3, :3]))
        assert np.isclose(volumes[name], det * volumes["identity"], rtol=1e-9), name


def test_orient_to_affine_reverses_only_mirrors():
    faces = np.array([[0, 1, 2], [2, 3, 0]])
    assert orient_to_affine(faces, np.eye(4)) is faces
    np.testing.assert_array_equal(orient_to_affine(faces, translated((1.0, 1.0, -0.5))),
                                  [[2, 1, 0], [0, 3, 2]])
    # two mirrors make a rotation: nothing to undo
    np.testing.assert_array_equal(orient_to_affine(faces, translated((-1.0, -1.0, 1.0))), faces)


def test_cli_remesh_of_a_mirrored_nifti_is_outward(tmp_path, capsys):
    affine = translated((-0.8, 0.8, 1.2), (40.0, -20.0, 5.0))  # radiological (x flipped) header
    source = tmp_path / "mask.nii"
    save_grid(VoxelGrid(l_solid(), affine, source="mask"), source)
    assert np.linalg.det(load_grid(source).affine[:3, :3]) < 0  # the mirror survives the file
    output = tmp_path / "mask.obj"
    assert main(["remesh", str(source), "-o", str(output), "--method", "surfacenets"]) == 0
    assert "surfacenets" in capsys.readouterr().out
    mesh = trimesh.load(output, force="mesh")
    assert mesh.is_watertight
    assert mesh.volume > 0
