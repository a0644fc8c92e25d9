"""The results report: its voxel picture geometry and a whole (small) report end to end."""

import numpy as np
import trimesh

from agndc_core.checkpoint import default_checkpoint_path
from agndc_core.grid import VoxelGrid
from agndc_core.report import build_report, voxel_faces


def test_voxel_faces_of_a_block_is_its_closed_box():
    occupancy = np.zeros((5, 5, 5), bool)
    occupancy[1:3, 1:4, 2:3] = True  # a 2 x 3 x 1 block of voxels
    grid = VoxelGrid.from_spacing(occupancy, voxel_size=0.5, origin=(1.0, 2.0, 3.0))
    vertices, faces = voxel_faces(grid)
    assert len(faces) == 2 * 2 * (2 * 3 + 2 * 1 + 3 * 1)  # two triangles per boundary face
    mesh = trimesh.Trimesh(vertices, faces)  # merges the shared corners
    assert mesh.is_watertight
    assert np.isclose(mesh.area, 2 * (1.0 * 1.5 + 1.0 * 0.5 + 1.5 * 0.5))
    # voxel (1, 1, 2) has its centre at origin + 0.5 * index; the block's min corner is half a
    # voxel below the first centre
    assert np.allclose(mesh.bounds[0], [1.0 + 0.25, 2.0 + 0.25, 3.0 + 0.75])


def test_report_on_a_small_folder(tmp_path):
    folder = tmp_path / "meshes"
    folder.mkdir()
    trimesh.creation.box((1.0, 0.6, 0.4)).export(folder / "box.stl")
    trimesh.creation.icosphere(3, 0.5).export(folder / "ball.obj")
    out = build_report(folder, tmp_path / "report" / "results.md", resolutions=(20,),
                       methods=("mc", "undc", "agndc", "oracle"), n_samples=5_000,
                       figure_shapes=("box",), command="agndc report test",
                       ablations={"w/o nothing": default_checkpoint_path("agndc")})
    text = out.read_text()
    assert "`agndc report test`" in text
    assert "## 20³: all shapes" in text and "| oracle | 2 |" in text
    assert "AGNDC against mc: CD " in text and "AGNDC against undc: CD " in text
    # an "ablation" that is the shipped checkpoint itself reproduces the agndc line exactly
    ablation = text.split("## Ablation")[1].split("\n\n")[1].splitlines()
    lines = {line.split(" | ")[0].strip("| "): line.split(" | ")[-5:] for line in ablation[2:]}
    assert list(lines) == ["undc", "w/o nothing", "agndc"]
    assert lines["w/o nothing"] == lines["agndc"]
    assert (out.parent / "results_rows" / "w_o_nothing.md").is_file()
    assert (out.parent / "results_rows" / "rows.csv").is_file()
    assert (out.parent / "results_shapes.png").stat().st_size > 10_000
