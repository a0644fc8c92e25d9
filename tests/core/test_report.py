"""The results report: its voxel picture geometry, the MC→oracle headroom shares and a whole
(small) report end to end."""

import csv
import math

import numpy as np
import pytest
import trimesh

from agndc_core.checkpoint import default_checkpoint_path
from agndc_core.errors import AGNDCError
from agndc_core.grid import VoxelGrid
from agndc_core.study.evaluate import (
    evaluate_meshes,
    grid_shifts,
    headroom_line,
    headroom_lines,
    headroom_shares,
    headroom_table,
    method_parts,
    parse_methods,
    read_rows,
    shift_table,
    summarize_rows,
    write_report,
)
from agndc_core.study.report import (
    FIGURE_COLOURS,
    FIGURE_SHAPES,
    REPORT_METHODS,
    SYNTHETIC_SHAPES,
    TILTED_BRACKET_DEGREES,
    build_report,
    figure_caption,
    rotated_box,
    tilted_bracket,
    voxel_faces,
)


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


def test_voxel_faces_face_out_of_the_voxels_under_any_affine():
    occupancy = np.zeros((5, 6, 7), dtype=bool)
    occupancy[1:4, 2:5, 1:3] = True
    occupancy[2, 2, 3] = True  # one voxel on top
    affine = np.diag([2.0, 2.0, 2.0, 1.0])
    affine[:3, 3] = (10.0, 0.0, -4.0)
    vertices, faces = voxel_faces(VoxelGrid(occupancy, affine))
    mesh = trimesh.Trimesh(vertices, faces)  # merges the quads' shared corners
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert mesh.volume == pytest.approx(occupancy.sum() * 8.0)  # outward: positive volume
    # voxel centres at the affine's index points, so the faces lie half a voxel beyond them
    np.testing.assert_allclose(mesh.bounds, [[10 + 2 * 0.5, 2 * 1.5, -4 + 2 * 0.5],
                                             [10 + 2 * 3.5, 2 * 4.5, -4 + 2 * 3.5]])


def summary(method, cd, ef1):
    return {"method": method, "cd": cd, "f1": 0.5, "nc": 0.9, "ecd": 0.1, "ef1": ef1}


def test_headroom_shares_from_the_means():
    summaries = [summary("mc", 10.0, 0.2), summary("a", 6.0, 0.35), summary("b", 12.0, 0.1),
                 summary("c", math.nan, 0.2), summary("oracle", 2.0, 0.7)]
    shares = headroom_shares(summaries)
    assert list(shares) == ["mc", "a", "b", "c", "oracle"]
    assert shares["mc"] == {"cd": 0.0, "ef1": 0.0}
    assert shares["oracle"] == {"cd": 100.0, "ef1": 100.0}
    assert np.isclose(shares["a"]["cd"], 50.0) and np.isclose(shares["a"]["ef1"], 30.0)
    assert np.isclose(shares["b"]["cd"], -25.0) and np.isclose(shares["b"]["ef1"], -20.0)
    assert math.isnan(shares["c"]["cd"]) and shares["c"]["ef1"] == 0.0
    line = headroom_line(summaries)
    assert line.startswith("Share of the MC→oracle headroom")
    assert "CD: mc 0.0 %, a 50.0 %, b -25.0 %, c –, oracle 100.0 %" in line
    assert "EF1: mc 0.0 %, a 30.0 %, b -20.0 %, c 0.0 %, oracle 100.0 %" in line
    # without both anchors there is nothing to share
    assert headroom_shares(summaries[:-1]) == {} and headroom_line(summaries[1:]) == ""
    # against the binary-input ceiling: the same shares of a smaller gap
    binary = summaries + [summary("oracle_binary", 6.0, 0.45)]
    shares = headroom_shares(binary, ceiling="oracle_binary")
    assert shares["a"]["cd"] == 100.0 and np.isclose(shares["a"]["ef1"], 60.0)
    assert np.isclose(shares["oracle"]["cd"], 200.0)
    lines = headroom_lines(binary)
    assert [line.split(" headroom")[0] for line in lines] == [
        "Share of the MC→oracle", "Share of the MC→oracle_binary"]
    assert headroom_lines(summaries) == [headroom_line(summaries)]


def test_headroom_table_per_category():
    def row(mesh, category, method, cd, ef1):
        return {"mesh": mesh, "category": category, "method": method, "cd": cd, "f1": 0.5,
                "nc": 0.9, "ecd": 0.1, "ef1": ef1, "seconds": 1.0}

    rows = []
    # CAD: one mesh, mc 10 -> ceiling 6; organic: two meshes, mc 4 -> ceiling 2 (means)
    meshes = (("p", "CAD", 10.0, 8.0, 6.0), ("q", "organic", 5.0, 3.0, 2.0),
              ("r", "organic", 3.0, 3.0, 2.0))
    for mesh, category, mc, a, top in meshes:
        rows += [row(mesh, category, "mc", mc, 0.1), row(mesh, category, "a", a, 0.2),
                 row(mesh, category, "oracle_binary", top, 0.3)]
    table = headroom_table(rows).splitlines()
    assert table[0] == "Share of the MC→oracle_binary headroom (CD / EF1)"
    assert table[2] == "| method | CAD (1) | organic (2) | all (3) |"
    # CAD (10 - 8) / (10 - 6); organic (4 - 3) / (4 - 2); all: means 6 -> 4.667 of 6 -> 3.333
    assert table[5] == "| a | 50.0 % / 50.0 % | 50.0 % / 50.0 % | 50.0 % / 50.0 % |"
    assert table[4].startswith("| mc | 0.0 % / 0.0 %")
    assert headroom_table([r for r in rows if r["method"] != "oracle_binary"]) == ""


def test_written_rows_read_back_with_float_metrics(tmp_path):
    row = {"mesh": "p.obj", "name": "p", "category": "CAD", "method": "mc", "resolution": 64,
           "shift": None, "cd": 2.5e-5, "f1": 0.5, "nc": 0.9, "ecd": math.nan, "ef1": math.nan,
           "seconds": 0.1, "error": ""}
    path = write_report([row], tmp_path)["csv"]
    with open(path, "a", newline="") as handle:  # a row without metrics: empty cells
        csv.writer(handle).writerow(["q.obj", "q", "CAD", "mc", 64, "", "", "", "", "", "", "",
                                     "failed"])
    back = read_rows(path)
    assert back[0]["cd"] == 2.5e-5 and back[0]["seconds"] == 0.1
    assert math.isnan(back[0]["ecd"]) and math.isnan(back[1]["cd"])
    assert math.isnan(back[1]["seconds"])
    assert (back[0]["name"], back[0]["resolution"], back[1]["error"]) == ("p", "64", "failed")


def test_rotated_box_is_a_closed_turned_box():
    vertices, faces = rotated_box()
    mesh = trimesh.Trimesh(vertices, faces)
    assert mesh.is_watertight and np.isclose(mesh.volume, 1.0 * 0.7 * 0.5)
    assert not np.allclose(np.abs(mesh.face_normals).max(axis=1), 1.0)  # off the axes


def test_tilted_bracket_is_a_closed_part_a_few_degrees_off_the_axes():
    vertices, faces = tilted_bracket()
    mesh = trimesh.Trimesh(vertices, faces)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    # two plates less two holes: 0.126 less 0.14 * pi * (0.1^2 + 0.09^2), up to the 64-gons
    assert mesh.volume == pytest.approx(0.126 - 0.14 * np.pi * (0.01 + 0.0081), rel=2e-3)
    # no face lies on a grid axis; the plates' faces (all but the holes' walls, ~90 % of the
    # area) are within the turn of one
    off_axis = np.degrees(np.arccos(np.abs(mesh.face_normals).max(axis=1).clip(max=1.0)))
    plates = off_axis <= TILTED_BRACKET_DEGREES + 1e-6
    assert off_axis.min() > 0.5
    assert 0.85 < mesh.area_faces[plates].sum() / mesh.area < 0.97


def test_the_picture_shows_a_cad_part_a_tilted_part_an_organic_and_a_printed_part():
    assert set(SYNTHETIC_SHAPES) <= set(FIGURE_SHAPES)
    for name in SYNTHETIC_SHAPES:
        vertices, faces = SYNTHETIC_SHAPES[name]()
        assert trimesh.Trimesh(vertices, faces).is_watertight
    caption = figure_caption(64, FIGURE_SHAPES)
    assert caption.startswith("Columns: marching cubes, surface nets, UNDC, AGNDC, ground truth")
    assert "tilted bracket" in caption and "rotated box" in caption
    assert "tilted bracket" not in figure_caption(64, ("fandisk",))


@pytest.mark.slow
def test_report_on_a_small_folder(tmp_path):
    folder = tmp_path / "meshes"
    folder.mkdir()
    trimesh.creation.box((1.0, 0.6, 0.4)).export(folder / "box.stl")
    trimesh.creation.icosphere(3, 0.5).export(folder / "ball.obj")
    out = build_report(folder, tmp_path / "report" / "results.md", resolutions=(20,),
                       methods=REPORT_METHODS, n_samples=5_000,
                       figure_shapes=("box",), command="agndc report test",
                       ablations={"w/o nothing": default_checkpoint_path("agndc")}, shifts=2)
    text = out.read_text()
    assert "`agndc report test`" in text
    assert "## 20³: all shapes" in text and "| oracle | 2 |" in text
    for method in ("mc_taubin", "surfacenets"):
        assert f"| {method} | 2 |" in text
    assert "AGNDC against mc: CD " in text and "AGNDC against undc: CD " in text
    assert "AGNDC against surfacenets: CD " in text
    assert "AGNDC+bounds against undc+bounds: CD " in text
    assert "AGNDC+bounds against surfacenets+bounds: CD " in text
    centred = text.split("## 20³ on 2 shifted grids per mesh")[0]
    for ceiling in ("oracle", "oracle_binary"):
        headroom = [line for line in centred.splitlines()
                    if line.startswith(f"Share of the MC→{ceiling} headroom")]
        assert len(headroom) == 1  # one resolution
        for method in REPORT_METHODS:
            assert f" {method} " in headroom[0]
        assert "CD: mc 0.0 %" in headroom[0] and "; EF1: mc " in headroom[0]
        assert f"{ceiling} 100.0 %" in headroom[0]
    # an "ablation" that is the shipped checkpoint itself reproduces the agndc line exactly
    ablation = text.split("## Ablation")[1].split("\n\n")[1].splitlines()
    lines = {line.split(" | ")[0].strip("| "): line.split(" | ")[-5:] for line in ablation[2:]}
    assert list(lines) == ["undc", "w/o nothing", "agndc"]
    assert lines["w/o nothing"] == lines["agndc"]
    assert (out.parent / "results_rows" / "w_o_nothing.md").is_file()
    assert (out.parent / "results_rows" / "rows.csv").is_file()
    picture = out.parent / "results_shapes.png"
    assert picture.stat().st_size > 10_000
    from PIL import Image

    with Image.open(picture) as image:  # a palette PNG, a fifth of the bytes of full colour
        assert image.mode == "P" and len(image.getpalette()) <= 3 * FIGURE_COLOURS
    # the shifted grids: the grid-alone methods only, both shifts, their own rows
    shifted = text.split("## 20³ on 2 shifted grids per mesh")[1].split("\n## ")[0]
    assert "| agndc | 2 |" in shifted and "| oracle | 2 |" in shifted
    assert "+bounds" not in shifted.split("Share of")[0]
    assert "AGNDC against undc: CD " in shifted and "AGNDC+bounds" not in shifted
    assert "| CD×10⁵ ↓ by shift | shift 0 | shift 1 | std of the shift means |" in shifted
    with open(out.parent / "results_rows" / "shifted" / "rows.csv") as handle:
        shifted_rows = list(csv.DictReader(handle))
    # 2 meshes x 2 shifts x the 8 grid-alone methods
    grid_alone = [m for m in REPORT_METHODS if "+bounds" not in m]
    assert len(grid_alone) == 8
    assert len(shifted_rows) == 2 * 2 * len(grid_alone)
    assert {r["shift"] for r in shifted_rows} == {"0", "1"}


def test_eval_uses_the_checkpoint_it_is_given(tmp_path, capsys):
    """``agndc eval --checkpoint agndc=PATH`` evaluates those weights, not the shipped ones: an
    untrained prior network is exactly surface nets, so its rows equal surfacenets' rows."""
    import csv

    import pytest
    import torch

    from agndc_core.checkpoint import save_checkpoint
    from agndc_core.cli import main
    from agndc_core.nn import AGNDCCascade, AGNDCConfig

    torch.manual_seed(0)
    weights = save_checkpoint(AGNDCCascade(AGNDCConfig(width=8)), tmp_path / "untrained",
                              training={}, metrics={})
    folder = tmp_path / "meshes"
    folder.mkdir()
    trimesh.creation.icosphere(3, 0.5).export(folder / "ball.obj")
    out = tmp_path / "eval"
    # an untrained cascade predicts the surface-nets vertices: as contoured (no normal filter,
    # which smooths a network's mesh), it is surface nets
    assert main(["eval", str(folder), "-o", str(out), "--methods", "agndc,surfacenets",
                 "--res", "24", "--samples", "5000", "--checkpoint",
                 f"agndc={weights}", "--no-normal-filter"]) == 0
    rows = {r["method"]: r for r in csv.DictReader(open(out / "rows.csv"))}
    assert rows["agndc"]["faces"] == rows["surfacenets"]["faces"]
    assert float(rows["agndc"]["cd"]) == pytest.approx(float(rows["surfacenets"]["cd"]),
                                                       rel=1e-6)
    # the same weights under a label of their own, beside the shipped agndc
    assert main(["eval", str(folder), "-o", str(out), "--methods",
                 "untrained=agndc,agndc,surfacenets", "--res", "24", "--samples", "5000",
                 "--checkpoint", f"untrained={weights}", "--no-normal-filter"]) == 0
    rows = {r["method"]: r for r in csv.DictReader(open(out / "rows.csv"))}
    assert float(rows["untrained"]["cd"]) == pytest.approx(float(rows["surfacenets"]["cd"]),
                                                           rel=1e-6)
    assert float(rows["agndc"]["cd"]) != pytest.approx(float(rows["surfacenets"]["cd"]),
                                                       rel=1e-3)  # the shipped weights
    # only learned methods take weights: a clear error (exit status 2), not a traceback
    assert main(["eval", str(folder), "--checkpoint", "mc=x"]) == 2
    assert "--checkpoint wants" in capsys.readouterr().err
    assert main(["eval", str(folder), "--methods", "a=mc", "--checkpoint", "a=x"]) == 2
    assert "--checkpoint wants" in capsys.readouterr().err


def test_method_entries_with_labels_and_bounds():
    assert method_parts("agndc") == ("agndc", "agndc", False)
    assert method_parts("agndc+bounds") == ("agndc+bounds", "agndc", True)
    assert method_parts("cpu3=agndc") == ("cpu3", "agndc", False)
    assert method_parts("cpu3b = undc+bounds") == ("cpu3b", "undc", True)
    assert parse_methods("mc, cpu3=agndc,agndc+bounds") == ["mc", "cpu3=agndc", "agndc+bounds"]
    for bad, words in (("mc,foo", "unknown"), ("x=foo", "unknown"), ("=agndc", "unknown"),
                       ("mc+bounds", "unknown"), ("agndc,agndc=undc", "given twice")):
        with pytest.raises(AGNDCError, match=words):
            parse_methods(bad)


def test_evaluation_on_shifted_grids(tmp_path):
    """``shifts=K`` scores each mesh on K seeded, moved grids: the shifts are reproducible and
    nested (the first K of a longer list), their rows differ from the centred grid's, and a
    mesh counts once in the means whatever K is."""
    first = grid_shifts(3, 1)
    assert np.array_equal(grid_shifts(3, 4)[:1], first) and np.array_equal(grid_shifts(3, 1), first)
    assert np.all(np.abs(grid_shifts(3, 4)) <= 0.5) and not np.allclose(grid_shifts(4, 1), first)
    path = tmp_path / "slab.stl"
    trimesh.creation.box((1.0, 0.6, 0.3), transform=trimesh.transformations.rotation_matrix(
        0.3, [1, 1, 0])).export(path)
    meshes = [(path, "mesh")]
    centred = evaluate_meshes(meshes, ["mc", "sn=surfacenets"], resolution=16, n_samples=4000,
                              progress=False)
    shifted = evaluate_meshes(meshes, ["mc", "sn=surfacenets"], resolution=16, n_samples=4000,
                              shifts=3, progress=False)
    assert [r["shift"] for r in centred] == [None, None]
    assert [(r["method"], r["shift"]) for r in shifted] == [
        ("mc", 0), ("sn", 0), ("mc", 1), ("sn", 1), ("mc", 2), ("sn", 2)]
    assert all(not r["error"] for r in centred + shifted)
    assert len({r["faces"] for r in shifted if r["method"] == "mc"} | {centred[0]["faces"]}) > 1
    summary = {s["method"]: s for s in summarize_rows(shifted)}
    assert summary["mc"]["shapes"] == 1
    assert summary["mc"]["cd"] == pytest.approx(np.mean([r["cd"] for r in shifted
                                                          if r["method"] == "mc"]))
    table = shift_table(shifted)
    assert "| CD×10⁵ ↓ by shift | shift 0 | shift 1 | shift 2 | std of the shift means |" in table
    cd_rows = [line for line in table.splitlines() if line.startswith("| sn |")]
    assert len(cd_rows) == 2  # CD and EF1
    values = [float(v) for v in cd_rows[0].strip("| ").split(" | ")[1:]]
    cds = [r["cd"] * 1e5 for r in shifted if r["method"] == "sn"]
    assert values[:3] == pytest.approx(cds, abs=1e-3)
    assert values[3] == pytest.approx(np.std(cds, ddof=1), abs=1e-3)


def test_models_table_says_where_the_weights_were_trained():
    """The training column names the last run's hardware and the lineage's total, and an old
    record without either reads as the CPU."""
    from agndc_core.study.report import _lineage_total, _trained_on

    gpu = {"lineage": [{"hardware": "CPU VM"}, {"hardware": "one NVIDIA H100, bf16 autocast"}],
           "total_train_seconds": 600.0}
    assert _trained_on(gpu) == "one NVIDIA H100"
    assert _lineage_total(gpu) == " (warm-started: 2 runs, 10 min of steps in all)"
    assert _trained_on({}) == "CPU" and _lineage_total({}) == ""
    assert _trained_on({"hardware": "CPU, 2 threads, torch 2.13"}) == "CPU"
    resumed = {"sessions": [{"hardware": "CPU, 2 threads"}, {"hardware": "CPU, 2 threads"},
                            {"hardware": "NVIDIA H200, bf16 autocast"}]}
    assert _trained_on(resumed) == "CPU + NVIDIA H200"


def test_models_table_says_when_the_weights_are_a_checkpoint_mid_schedule():
    from agndc_core.study.report import _steps_trained

    final = {"steps_per_scale": [3000, 300, 300], "steps_done": {"scale": 0, "step": 3000}}
    assert _steps_trained(final) == "3000/300/300 steps at scales 0/1/2"
    middle = {"steps_per_scale": [4000, 0, 0], "steps_done": {"scale": 0, "step": 2000}}
    assert _steps_trained(middle) == "2000 of 4000/0/0 steps at scales 0/1/2"
    assert _steps_trained({"steps_per_scale": [2300]}) == "2300 steps at scales 0"


@pytest.mark.slow
def test_demo_the_readme_opens_with(tmp_path, capsys):
    """``agndc demo`` (the README's first command, at a small size): every method's mesh, the
    grid, and a table with one row per method."""
    from agndc_core.cli import main

    out = tmp_path / "demo"
    assert main(["demo", "-o", str(out), "--res", "24"]) == 0
    table = capsys.readouterr().out
    for method in ("mc", "mc_taubin", "surfacenets", "oracle", "undc", "agndc"):
        assert (out / f"part_{method}.obj").stat().st_size > 1000
        assert f"| {method} | 1 |" in table
    assert (out / "part.obj").is_file() and (out / "part_grid.npz").is_file()
