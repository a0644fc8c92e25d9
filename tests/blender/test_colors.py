"""A coloured MagicaVoxel file imports with its colours: one material per used palette colour
(Principled BSDF base colour = the palette colour), faces assigned by the nearest source voxel,
on the result and on the marching-cubes mesh beside it; the mesh stays closed."""

import bpy
import numpy as np
import pytest

pytestmark = pytest.mark.blender

RED, BLUE = 36, 200  # default-palette indices: (255, 0, 0) and (0, 102, 204)


def _coloured_vox(path, palette=None):
    """A 10 x 6 x 6 box, RED for x < 5, BLUE from x = 5, written with the core's write_vox."""
    from agndc_core.formats.vox import write_vox

    indices = np.zeros((12, 8, 8), dtype=np.uint8)
    indices[1:6, 1:7, 1:7] = RED
    indices[6:11, 1:7, 1:7] = BLUE
    path.write_bytes(write_vox(indices != 0, path.name, colors=indices, palette=palette))
    return indices


def _face_arrays(obj):
    """(F, 3) polygon centres (local) and (F,) material slots of an object's mesh."""
    mesh = obj.data
    centres = np.zeros(len(mesh.polygons) * 3, dtype=np.float32)
    mesh.polygons.foreach_get("center", centres)
    slots = np.zeros(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("material_index", slots)
    return centres.reshape(-1, 3), slots


def _base_color(material):
    shader = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    return np.array(shader.inputs["Base Color"].default_value)


def test_coloured_vox_imports_with_its_colours(addon, tmp_path):
    from agndc_core.colors import srgb_to_linear
    from agndc_core.formats.vox_palette import default_palette
    from agndc_core.meshcheck import topology_violations

    path = tmp_path / "castle.vox"
    _coloured_vox(path)
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="agndc",
                                          compare_mc=True) == {"FINISHED"}
    palette = default_palette()
    for name in ("castle_AGNDC", "castle_MC"):
        obj = bpy.data.objects[name]
        names = [m.name for m in obj.data.materials]
        assert names == ["vox_ff0000", "vox_0066cc"], name  # palette index order
        for material, index in zip(obj.data.materials, (RED, BLUE)):
            np.testing.assert_allclose(_base_color(material), srgb_to_linear(palette[index]),
                                       atol=1e-6)
        centres, slots = _face_arrays(obj)
        # local coordinates are the grid's (.vox: voxel size 1, origin 0): layers 5 | 6 meet
        # at x = 5.5
        x = centres[:, 0]
        assert np.all(slots[x < 5.0] == 0) and np.all(slots[x > 6.0] == 1), name
        assert (slots == 0).sum() > 50 and (slots == 1).sum() > 50
        vertices, faces = addon.mesh_io.mesh_arrays(obj.data)
        assert not any(topology_violations(vertices, faces).values()), name
    # the materials are shared by name: a second import reuses them
    count = len(bpy.data.materials)
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="mc") == {"FINISHED"}
    assert len(bpy.data.materials) == count


def test_file_palette_and_colours_off(addon, tmp_path):
    palette = np.zeros((256, 4), dtype=np.uint8)
    palette[RED], palette[BLUE] = (10, 200, 30, 255), (250, 250, 0, 255)
    path = tmp_path / "tinted.vox"
    _coloured_vox(path, palette)
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="mc") == {"FINISHED"}
    obj = bpy.data.objects["tinted_MC"]
    assert [m.name for m in obj.data.materials] == ["vox_0ac81e", "vox_fafa00"]
    assert bpy.ops.import_mesh.agndc_grid(filepath=str(path), method="mc",
                                          colors=False) == {"FINISHED"}
    obj = bpy.data.objects["tinted_MC"]  # replaced by the uncoloured import
    assert len(obj.data.materials) == 0


def test_cli_glb_imports_into_blender_with_its_colours(addon, tmp_path):
    """What ``agndc remesh castle.vox castle.glb`` writes, read by Blender's own glTF importer:
    one object per colour, each with its material's base colour."""
    from agndc_core.cli import main
    from agndc_core.colors import srgb_to_linear
    from agndc_core.formats.vox_palette import default_palette

    path = tmp_path / "castle.vox"
    _coloured_vox(path)
    assert main(["remesh", str(path), "-o", str(tmp_path / "castle.glb"), "--method", "mc"]) == 0
    assert bpy.ops.import_scene.gltf(filepath=str(tmp_path / "castle.glb")) == {"FINISHED"}
    palette = default_palette()
    for index in (RED, BLUE):
        material = bpy.data.materials[f"vox_{bytes(palette[index][:3]).hex()}"]
        np.testing.assert_allclose(_base_color(material), srgb_to_linear(palette[index]),
                                   atol=1e-6)
        users = [o for o in bpy.data.objects if o.type == "MESH"
                 and material.name in [m.name for m in o.data.materials]]
        assert len(users) == 1 and len(users[0].data.polygons) > 50
