"""Colours of .vox grids: palette reading (file and default), colour indices through
write_vox/read_vox, face colours of remeshed meshes, coloured .glb/.ply files and the CLI."""

import json
import struct

import numpy as np
import pytest
import trimesh

from agndc_core.cli import main
from agndc_core.colors import (
    VoxelColors,
    face_colors,
    group_faces,
    material_name,
    material_slots,
    result_colors,
    srgb_to_linear,
)
from agndc_core.formats.vox import read_vox, read_vox_colors, write_vox
from agndc_core.formats.vox_palette import default_palette
from agndc_core.grid import VoxelGrid
from agndc_core.gridio import load_grid, save_grid, save_mesh
from agndc_core.meshcheck import topology_violations
from agndc_core.pipeline import remesh

RED, BLUE = 36, 200  # indices whose default colours are pure red and a blue (spec table)


def two_colour_box(shape=(10, 6, 6), split=5):
    """A box filling the grid but a one-voxel margin, index RED below x = ``split``, BLUE from
    it: (X, Y, Z) uint8 indices."""
    indices = np.zeros(shape, dtype=np.uint8)
    indices[1:split, 1:-1, 1:-1] = RED
    indices[split:-1, 1:-1, 1:-1] = BLUE
    return indices


def custom_palette() -> np.ndarray:
    """(256, 4) uint8: index i is (i, 255 - i, 2 i mod 256, 255); index 0 transparent."""
    i = np.arange(256)
    palette = np.stack([i, 255 - i, (2 * i) % 256, np.full(256, 255)], axis=1).astype(np.uint8)
    palette[0] = 0
    return palette


def coloured_grid(indices, palette=None, affine=None) -> VoxelGrid:
    palette = default_palette() if palette is None else palette
    return VoxelGrid(indices != 0, np.eye(4) if affine is None else affine,
                     colors=VoxelColors(indices, palette))


# --- palette and indices ----------------------------------------------------------------------


def test_default_palette_matches_the_spec_table():
    palette = default_palette()
    assert palette.shape == (256, 4) and palette.dtype == np.uint8
    # spec words 0xAABBGGRR: 0xffffffff white, 0xffccffff (R ff, G ff, B cc), 0xff0000ff red,
    # 0xff111111 the last grey; entry 0 unused
    assert palette[0].tolist() == [0, 0, 0, 0]
    assert palette[1].tolist() == [255, 255, 255, 255]
    assert palette[2].tolist() == [255, 255, 204, 255]
    assert palette[RED].tolist() == [255, 0, 0, 255]
    assert palette[255].tolist() == [17, 17, 17, 255]
    assert len({tuple(c) for c in palette[1:]}) == 255  # every colour distinct


def test_file_without_rgba_chunk_reads_the_default_palette():
    indices = two_colour_box()
    data = write_vox(indices != 0, "box.vox", colors=indices)
    assert b"RGBA" not in data
    read, palette = read_vox_colors(data, "box.vox")
    np.testing.assert_array_equal(read, indices)
    np.testing.assert_array_equal(palette, default_palette())


def test_rgba_chunk_maps_entry_k_to_index_k_plus_one():
    indices = two_colour_box()
    data = write_vox(indices != 0, "box.vox", colors=indices, palette=custom_palette())
    # the chunk itself, as the spec lays it out: entry k is the colour of index k + 1
    at = data.index(b"RGBA")
    content, children = struct.unpack_from("<ii", data, at + 4)
    assert (content, children) == (1024, 0)
    chunk = np.frombuffer(data, np.uint8, 1024, at + 12).reshape(256, 4)
    assert chunk[RED - 1].tolist() == [RED, 255 - RED, 2 * RED, 255]
    read, palette = read_vox_colors(data, "box.vox")
    np.testing.assert_array_equal(read, indices)
    np.testing.assert_array_equal(palette[1:], custom_palette()[1:])


def test_read_vox_stays_occupancy_and_colours_round_trip_through_files(tmp_path):
    indices = two_colour_box()
    indices[3, 2, 2] = 7  # a third colour inside
    data = write_vox(indices != 0, "box.vox", colors=indices)
    occupancy = read_vox(data, "box.vox")
    assert occupancy.dtype == bool
    np.testing.assert_array_equal(occupancy, indices != 0)
    save_grid(coloured_grid(indices, custom_palette()), tmp_path / "box.vox")
    grid = load_grid(tmp_path / "box.vox")
    np.testing.assert_array_equal(grid.colors.indices, indices)
    np.testing.assert_array_equal(grid.colors.palette[1:], custom_palette()[1:])
    assert grid.colors.used.tolist() == [7, RED, BLUE]


def test_uncoloured_formats_and_mismatched_colours():
    assert VoxelGrid(np.ones((3, 3, 3), bool)).colors is None
    with pytest.raises(Exception, match="do not match"):
        VoxelGrid(np.ones((3, 3, 3), bool),
                  colors=VoxelColors(np.ones((3, 3, 4), np.uint8), default_palette()))


# --- face colours -----------------------------------------------------------------------------


@pytest.mark.parametrize("method", ["mc", "surfacenets"])
def test_each_half_of_a_two_colour_box_gets_its_colour(method):
    grid = coloured_grid(two_colour_box(), affine=np.diag([0.5, 0.5, 0.5, 1.0]))
    result = remesh(grid, method=method)
    index = face_colors(result.vertices, result.faces, grid)
    assert index.shape == (len(result.faces),) and index.dtype == np.uint8
    x = grid.world_to_index(result.vertices[result.faces].mean(axis=1))[:, 0]  # (F,)
    # the split lies between voxel layers 4 and 5 (x = 4.5); faces clear of it by half a voxel
    assert np.all(index[x < 4.0] == RED) and np.all(index[x > 5.0] == BLUE)
    assert (index == RED).sum() > 20 and (index == BLUE).sum() > 20


def test_a_thin_wall_of_two_colours_gives_each_side_its_colour():
    """A wall two voxels thick, one voxel layer per colour: the faces of each side (outward
    normal -x or +x) take that side's layer, also under a mirroring affine."""
    indices = np.zeros((6, 10, 10), dtype=np.uint8)
    indices[2, 1:-1, 1:-1], indices[3, 1:-1, 1:-1] = RED, BLUE
    for affine in (np.eye(4), np.diag([-1.0, 1.0, 1.0, 1.0])):
        grid = coloured_grid(indices, affine=affine)
        result = remesh(grid, method="mc")
        corners = grid.world_to_index(result.vertices)[result.faces]  # (F, 3, 3)
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        normal *= np.sign(np.linalg.det(affine[:3, :3]))  # outward in index space
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        index = face_colors(result.vertices, result.faces, grid)
        assert np.all(index[normal[:, 0] < -0.9] == RED)
        assert np.all(index[normal[:, 0] > 0.9] == BLUE)


def test_learned_method_colours_and_grouping():
    grid = coloured_grid(two_colour_box((14, 8, 8), split=7))
    result = remesh(grid, method="agndc")
    colors = result_colors(result)
    index = colors["face_colors"]
    assert set(index.tolist()) == {RED, BLUE}
    used, slot = material_slots(index)
    assert used.tolist() == [RED, BLUE] and slot.dtype == np.int32
    np.testing.assert_array_equal(used[slot], index)
    groups = group_faces(index)
    assert list(groups) == [RED, BLUE]
    assert sum(len(g) for g in groups.values()) == len(result.faces)
    assert np.all(index[groups[RED]] == RED)


def test_srgb_to_linear_and_names():
    linear = srgb_to_linear(np.array([[0, 128, 255, 255]], dtype=np.uint8))
    np.testing.assert_allclose(linear, [[0.0, 0.2158605, 1.0, 1.0]], atol=1e-6)
    assert material_name(np.array([255, 0, 16, 255])) == "vox_ff0010"


# --- files ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def box_result():
    grid = coloured_grid(two_colour_box())
    return remesh(grid, method="mc")


def test_glb_has_one_material_per_colour_and_welds_to_the_closed_mesh(box_result, tmp_path):
    colors = result_colors(box_result)
    path = tmp_path / "box.glb"
    save_mesh(box_result.vertices, box_result.faces, path, **colors)
    scene = trimesh.load(path)
    names = sorted(scene.geometry)
    palette = default_palette()
    assert names == sorted([material_name(palette[RED]), material_name(palette[BLUE])])
    for index in (RED, BLUE):
        part = scene.geometry[material_name(palette[index])]
        assert len(part.faces) == int((colors["face_colors"] == index).sum())
        assert part.visual.material.name == material_name(palette[index])
    # the glTF itself: exact linear base colours, not metallic
    data = path.read_bytes()
    length = struct.unpack_from("<I", data, 12)[0]
    materials = {m["name"]: m["pbrMetallicRoughness"]
                 for m in json.loads(data[20:20 + length])["materials"]}
    red = materials[material_name(palette[RED])]
    assert red["baseColorFactor"] == [1.0, 0.0, 0.0, 1.0] and red["metallicFactor"] == 0.0
    np.testing.assert_allclose(materials[material_name(palette[BLUE])]["baseColorFactor"],
                               srgb_to_linear(palette[BLUE]))
    parts = trimesh.util.concatenate(list(scene.geometry.values()))
    welded = trimesh.Trimesh(parts.vertices, parts.faces)  # merges equal positions
    assert not any(topology_violations(welded.vertices, welded.faces).values())
    assert welded.is_volume


def test_ply_has_face_colours_and_stays_closed(box_result, tmp_path):
    colors = result_colors(box_result)
    path = tmp_path / "box.ply"
    save_mesh(box_result.vertices, box_result.faces, path, **colors)
    mesh = trimesh.load(path, process=False)
    np.testing.assert_array_equal(mesh.faces, box_result.faces)
    np.testing.assert_array_equal(mesh.visual.face_colors,
                                  default_palette()[colors["face_colors"]])
    assert not any(topology_violations(mesh.vertices, mesh.faces).values())


def test_cli_writes_colours_unless_told_not_to(tmp_path, capsys):
    source = tmp_path / "box.vox"
    indices = two_colour_box()
    source.write_bytes(write_vox(indices != 0, "box.vox", colors=indices))
    assert main(["remesh", str(source), "-o", str(tmp_path / "box.glb"), "--method", "mc"]) == 0
    assert "2 colours" in capsys.readouterr().out
    assert len(trimesh.load(tmp_path / "box.glb").geometry) == 2
    assert main(["remesh", str(source), "-o", str(tmp_path / "plain.glb"), "--method", "mc",
                 "--no-colors"]) == 0
    assert len(trimesh.load(tmp_path / "plain.glb").geometry) == 1
    assert main(["remesh", str(source), "-o", str(tmp_path / "box.obj"), "--method", "mc"]) == 0
    plain = tmp_path / "plain.obj"
    assert main(["remesh", str(source), "-o", str(plain), "--method", "mc", "--no-colors"]) == 0
    assert (tmp_path / "box.obj").read_bytes() == plain.read_bytes()  # .obj: geometry only


def test_voxel_house_keeps_every_colour_on_a_closed_agndc_mesh():
    """The docs' six-colour house (study/voxel_art.py): every colour reaches the AGNDC mesh,
    which stays closed, and the door's faces are the door's colour."""
    from agndc_core.study.voxel_art import HOUSE_COLORS, house

    grid = house()
    result = remesh(grid, method="agndc")
    assert not any(topology_violations(result.vertices, result.faces).values())
    index = face_colors(result.vertices, result.faces, grid)
    assert set(index.tolist()) == set(HOUSE_COLORS)
    centre = grid.world_to_index(result.vertices[result.faces].mean(axis=1))  # (F, 3)
    # the door: voxels x 10..13, z 2..8 of the front wall's outer layer (y = 4)
    door = (centre[:, 1] < 4.0) & (np.abs(centre[:, 0] - 11.5) < 1.2) & (centre[:, 2] > 3) \
        & (centre[:, 2] < 7.5)
    assert door.sum() >= 10 and np.all(index[door] == 3)


def test_batch_writes_the_colours_of_vox_inputs(tmp_path):
    from agndc_core import batch

    indices = two_colour_box()
    (tmp_path / "box.vox").write_bytes(write_vox(indices != 0, "box.vox", colors=indices))
    out = tmp_path / "out"
    (row,) = batch.remesh_many([tmp_path / "box.vox"], out, method="mc", workers=1)
    assert row["status"] == "ok"
    mesh = trimesh.load(out / "box.ply", process=False)
    colours = {tuple(c) for c in mesh.visual.face_colors.tolist()}
    assert colours == {tuple(default_palette()[RED]), tuple(default_palette()[BLUE])}
