"""Tests of agndc_core.study.shapes: validity, normalisation, determinism, family mix and
diversity."""

import time

import numpy as np
import pytest
import trimesh

from agndc_core.study.shapes import (
    AXIS_ALIGNED_FRACTION,
    FAMILIES,
    FAMILY_WEIGHTS,
    generate_dataset,
    generate_shape,
    is_axis_aligned,
    layered_shape,
    round_aligned,
    round_shape,
    shape_family,
    sheet_shape,
    spiky_shape,
    strut,
    strut_shape,
)
from agndc_core.training.data import (
    LAYER_VOXELS,
    RESOLUTION_RANGE,
    SHEET_VOXELS,
    TILT_DEGREES,
    WRINKLE_AMPLITUDE,
    WRINKLE_WAVELENGTH,
    WRINKLE_WAVES,
    WRINKLED_FAMILIES,
    make_sample,
    recipe_mesh,
    sample_recipe,
)

#: the first few seeds of every family, so each family's builders are exercised
PER_FAMILY = 6
SEEDS = sorted(s for fam in FAMILIES
               for s in [s for s in range(300) if shape_family(s) == fam][:PER_FAMILY])
#: seeds over which the (cheap) family and alignment draws are counted
N_COUNT = 4000
#: allowed deviation of a share from its target over N_COUNT seeds (~4 standard deviations)
SHARE_TOL = 0.03
#: a face normal counts as axis-aligned when its largest component is within this of 1
AXIS_TOL = 1e-6
#: the issue's budget: average seconds to generate one shape
MEAN_SECONDS = 0.5


@pytest.fixture(scope="module")
def meshes():
    """seed -> trimesh.Trimesh (unprocessed, so the generator's arrays are tested as-is)."""
    out, t0 = {}, time.perf_counter()
    for seed in SEEDS:
        out[seed] = trimesh.Trimesh(*generate_shape(seed), process=False)
    out["seconds"] = (time.perf_counter() - t0) / len(SEEDS)
    return out


@pytest.mark.parametrize("seed", SEEDS)
def test_watertight_outward_normalised_solid(meshes, seed):
    mesh = meshes[seed]
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    assert len(mesh.faces) >= 12
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.is_volume
    assert mesh.volume > 0  # consistent winding and positive volume: outward normals
    lo, hi = mesh.bounds
    assert (hi - lo).max() == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose((lo + hi) / 2, 0.0, atol=1e-9)


def test_generation_is_fast(meshes):
    assert meshes["seconds"] < MEAN_SECONDS


@pytest.mark.parametrize("family", FAMILIES)
def test_deterministic_and_seed_dependent(family):
    seed, other = [s for s in range(300) if shape_family(s) == family][:2]
    v1, f1 = generate_shape(seed)
    v2, f2 = generate_shape(seed)
    np.testing.assert_array_equal(v1, v2)
    np.testing.assert_array_equal(f1, f2)
    v3, _ = generate_shape(other)
    assert v1.shape != v3.shape or not np.array_equal(v1, v3)


def test_family_and_alignment_shares():
    families = np.array([shape_family(s) for s in range(N_COUNT)])
    for family, weight in zip(FAMILIES, FAMILY_WEIGHTS):
        assert np.mean(families == family) == pytest.approx(weight, abs=SHARE_TOL), family
    aligned = np.mean([is_axis_aligned(s) for s in range(N_COUNT)])
    assert aligned == pytest.approx(AXIS_ALIGNED_FRACTION, abs=SHARE_TOL)


def test_recipes_rotate_once_and_draw_log_uniform_resolutions():
    recipes = [sample_recipe(s) for s in range(N_COUNT // 2)]
    # the generator rotates the non-aligned shapes itself: recipes never add a second rotation
    assert all(np.array_equal(r["rotation"], np.eye(3)) for r in recipes)
    aligned = np.mean([r["axis_aligned"] for r in recipes])
    assert aligned == pytest.approx(AXIS_ALIGNED_FRACTION, abs=1.5 * SHARE_TOL)
    assert all(r["family"] == shape_family(r["seed"]) for r in recipes)
    res = np.array([r["resolution"] for r in recipes])
    lo, hi = RESOLUTION_RANGE
    assert res.min() == lo and res.max() == hi
    mid = np.sqrt(lo * hi)  # log-uniform: half the draws on each side of the geometric mean
    assert np.mean(res < mid) == pytest.approx(0.5, abs=0.05)
    # an extra rotation only for generator-aligned shapes
    turned = [r for r in (sample_recipe(s, rotate_fraction=1.0) for s in range(200))
              if not np.array_equal(r["rotation"], np.eye(3))]
    assert turned and all(is_axis_aligned(r["seed"]) and not r["axis_aligned"] for r in turned)


def test_wrinkled_recipes_keep_their_other_draws_and_give_closed_wrinkled_meshes():
    seeds = range(300)
    plain = [sample_recipe(s) for s in seeds]
    wrinkled = [sample_recipe(s, wrinkled=0.5) for s in seeds]
    for a, b in zip(plain, wrinkled):
        assert {k: v for k, v in b.items() if k != "wrinkles"} == a and "wrinkles" not in a
    chosen = [r for r in wrinkled if "wrinkles" in r]
    eligible = [r for r in wrinkled if r["family"] in WRINKLED_FAMILIES]
    assert all(r["family"] in WRINKLED_FAMILIES for r in chosen)
    assert len(chosen) / len(eligible) == pytest.approx(0.5, abs=0.15)
    waves = chosen[0]["wrinkles"]
    assert len(waves["wavelength"]) == WRINKLE_WAVES
    assert WRINKLE_WAVELENGTH[0] <= min(waves["wavelength"]) <= WRINKLE_WAVELENGTH[1]
    unwrinkled = {k: v for k, v in chosen[0].items() if k != "wrinkles"}
    smooth = trimesh.Trimesh(*recipe_mesh(unwrinkled), process=False)
    mesh = trimesh.Trimesh(*recipe_mesh(chosen[0]), process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    # subdivided finer than the shortest wave (an edge then stretches by at most both ends'
    # displacements), every vertex within the summed amplitudes of the smooth surface, and the
    # surface really moved
    edges = np.linalg.norm(np.diff(mesh.vertices[mesh.edges_unique], axis=1)[:, 0], axis=1)
    assert edges.max() <= min(waves["wavelength"]) / 4 + 2 * sum(waves["amplitude"])
    assert len(mesh.faces) > 4 * len(smooth.faces)
    distance = np.abs(trimesh.proximity.signed_distance(smooth, mesh.vertices[::50]))
    assert distance.max() <= sum(waves["amplitude"]) + 1e-6
    assert distance.mean() > 0.2 * WRINKLE_AMPLITUDE[0]


def test_sheet_recipes_keep_the_other_seeds_and_give_thin_closed_plates():
    seeds = range(300)
    plain = [sample_recipe(s, wrinkled=0.5) for s in seeds]
    mixed = [sample_recipe(s, wrinkled=0.5, sheets=0.2) for s in seeds]
    sheets = [b for b in mixed if "sheet_voxels" in b]
    assert len(sheets) / len(mixed) == pytest.approx(0.2, abs=0.07)
    for a, b in zip(plain, mixed):
        if "sheet_voxels" in b:  # the same grid, another shape, never wrinkled
            assert b["family"] == "sheet" and "wrinkles" not in b
            assert SHEET_VOXELS[0] <= b["sheet_voxels"] <= SHEET_VOXELS[1]
            assert {k: b[k] for k in ("resolution", "shift", "rotation")} == {
                k: a[k] for k in ("resolution", "shift", "rotation")}
        else:
            assert b == a
    # an aligned sheet is as thick as asked, in voxels of its own grid, and closed
    recipe = next(r for r in sheets if r["axis_aligned"] and r["resolution"] <= 64)
    mesh = trimesh.Trimesh(*recipe_mesh(recipe), process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    extent = np.sort(mesh.bounds[1] - mesh.bounds[0])
    assert extent[-1] == pytest.approx(1.0, abs=1e-6)
    assert extent[0] * (recipe["resolution"] - 2) == pytest.approx(recipe["sheet_voxels"],
                                                                   rel=1e-6)
    sample = make_sample(recipe)
    occupied = sample["lattice"].any(axis=tuple(a for a in range(3) if a != np.argmin(
        sample["lattice"].shape)))
    assert 1 <= occupied.sum() <= np.ceil(recipe["sheet_voxels"]) + 1
    # deterministic, and thicker when asked
    v, f = sheet_shape(recipe["seed"], 0.05)
    np.testing.assert_array_equal(v, sheet_shape(recipe["seed"], 0.05)[0])
    assert np.sort(v.max(0) - v.min(0))[0] == pytest.approx(0.05, rel=1e-6)


def test_tilted_recipes_turn_only_aligned_shapes_slightly_and_keep_the_other_draws():
    seeds = range(400)
    plain = [sample_recipe(s, wrinkled=0.5, sheets=0.2) for s in seeds]
    tilted = [sample_recipe(s, wrinkled=0.5, sheets=0.2, tilted=0.6) for s in seeds]
    turned = [b for b in tilted if "tilt_degrees" in b]
    candidates = [a for a in plain if a["axis_aligned"] and "sheet_voxels" not in a]
    assert len(turned) / len(candidates) == pytest.approx(0.6, abs=0.12)
    for a, b in zip(plain, tilted):
        if "tilt_degrees" not in b:
            assert b == a
            continue
        assert a["axis_aligned"] and "sheet_voxels" not in a and not b["axis_aligned"]
        assert {k: v for k, v in b.items() if k not in ("rotation", "axis_aligned",
                                                         "tilt_degrees")} == {
            k: v for k, v in a.items() if k not in ("rotation", "axis_aligned")}
        turn = np.asarray(b["rotation"])
        np.testing.assert_allclose(turn @ turn.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(turn) == pytest.approx(1.0)
        assert TILT_DEGREES[0] - 1e-9 <= b["tilt_degrees"] <= TILT_DEGREES[1] + 1e-9
    # the mesh is the aligned shape turned: its flat faces leave the axes by the tilt at most,
    # and its largest face by more than a degree
    recipe = turned[0]
    aligned = trimesh.Trimesh(*recipe_mesh({**recipe, "rotation": np.eye(3).tolist()}),
                              process=False)
    mesh = trimesh.Trimesh(*recipe_mesh(recipe), process=False)
    np.testing.assert_allclose(mesh.vertices, aligned.vertices @ np.asarray(
        recipe["rotation"]).T, atol=1e-12)
    largest = np.argmax(mesh.area_faces)
    off_axis = np.degrees(np.arccos(np.abs(mesh.face_normals[largest]).max()))
    assert 1.0 - 1e-6 < off_axis <= recipe["tilt_degrees"] + 1e-6
    assert np.abs(aligned.face_normals[largest]).max() > 1 - AXIS_TOL


def _on_grid_share(mesh) -> float:
    """Share of the surface area whose normal is a grid axis."""
    on_grid = np.abs(mesh.face_normals).max(axis=1) > 1 - AXIS_TOL
    return mesh.area_faces[on_grid].sum() / mesh.area


def test_diversity(meshes):
    ms = [meshes[s] for s in SEEDS]
    n_comp = [len(m.split(only_watertight=False)) for m in ms]
    # genus summed over components from the Euler characteristic: chi = sum(2 - 2 g_i)
    genus = [(2 * c - m.euler_number) // 2 for m, c in zip(ms, n_comp)]
    assert sum(g > 0 for g in genus) >= 3  # through-holes, tubes, tori
    assert sum(c > 1 for c in n_comp) >= 1  # several disjoint parts
    on_grid = np.array([_on_grid_share(m) for m in ms])
    aligned = np.array([is_axis_aligned(s) for s in SEEDS])
    # a freely rotated shape has no face on the grid axes; an aligned CAD part mostly has
    assert np.all(on_grid[~aligned] < 0.01)
    cad_aligned = aligned & np.array([shape_family(s) == "cad" for s in SEEDS])
    assert np.any(on_grid[cad_aligned] > 0.5)
    assert len({len(m.faces) for m in ms}) >= 0.8 * len(ms)  # not the same few templates


@pytest.mark.parametrize("family", ["smooth", "organic"])
def test_curved_families_have_no_large_flat_faces(meshes, family):
    for seed in (s for s in SEEDS if shape_family(s) == family):
        mesh = meshes[seed]
        # curved surfaces are finely tessellated: no triangle carries a big share of the area
        assert len(mesh.faces) > 500
        assert np.median(mesh.area_faces) / mesh.area < 1e-3


def test_generate_dataset_matches_generate_shape():
    rows = list(generate_dataset(2, seed0=5))
    assert [r[0] for r in rows] == [5, 6]
    np.testing.assert_array_equal(rows[1][1], generate_shape(6)[0])


def test_spike_recipes_keep_the_other_draws_and_grow_closed_sharp_spikes():
    seeds = range(300)
    plain = [sample_recipe(s, wrinkled=0.5, sheets=0.2, tilted=0.3) for s in seeds]
    spiky = [sample_recipe(s, wrinkled=0.5, sheets=0.2, tilted=0.3, spikes=0.25) for s in seeds]
    grown = [b for b in spiky if b.get("spikes")]
    candidates = [a for a in plain if "sheet_voxels" not in a]
    assert len(grown) / len(candidates) == pytest.approx(0.25, abs=0.08)
    for a, b in zip(plain, spiky):
        if not b.get("spikes"):
            assert b == a
            continue
        assert "sheet_voxels" not in a and "wrinkles" not in b
        assert {k: v for k, v in b.items() if k != "spikes"} == {
            k: v for k, v in a.items() if k != "wrinkles"}
    # closed, outward, and sharper than the shape it grew from: spike tips are vertices whose
    # angular defect exceeds pi (a cone of half-angle a has 2 pi (1 - sin a))
    for recipe in grown[:4]:
        mesh = trimesh.Trimesh(*recipe_mesh(recipe), process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        base = trimesh.Trimesh(*generate_shape(recipe["seed"]), process=False)
        assert (mesh.vertex_defects > np.pi).sum() >= (base.vertex_defects > np.pi).sum() + 2
    v, f = spiky_shape(grown[0]["seed"], 1 / 62)  # deterministic, normalised
    np.testing.assert_array_equal(v, spiky_shape(grown[0]["seed"], 1 / 62)[0])
    assert np.ptp(v, axis=0).max() == pytest.approx(1.0, abs=1e-12)
    sample = make_sample(grown[0])
    assert sample["lattice"].any()


def test_layered_recipes_keep_the_other_draws_and_stack_layers_a_voxel_thick():
    seeds = range(300)
    plain = [sample_recipe(s, wrinkled=0.5, sheets=0.2, tilted=0.3, spikes=0.2) for s in seeds]
    layered = [sample_recipe(s, wrinkled=0.5, sheets=0.2, tilted=0.3, spikes=0.2, layered=0.3)
               for s in seeds]
    made = [b for b in layered if "layer_voxels" in b]
    candidates = [a for a in plain if "sheet_voxels" not in a and not a.get("spikes")]
    assert len(made) / len(candidates) == pytest.approx(0.3, abs=0.08)
    for a, b in zip(plain, layered):
        if "layer_voxels" not in b:
            assert b == a
            continue
        assert "sheet_voxels" not in a and not a.get("spikes") and "wrinkles" not in b
        assert b["family"] == "layered" and LAYER_VOXELS[0] <= b["layer_voxels"] <= LAYER_VOXELS[1]
        assert b["rotation"] == np.eye(3).tolist() and "tilt_degrees" not in b
        assert b["axis_aligned"] == is_axis_aligned(b["seed"])
        placement = ("family", "layer_voxels", "rotation", "axis_aligned", "tilt_degrees")
        assert {k: v for k, v in b.items() if k not in placement} == {
            k: v for k, v in a.items() if k not in (*placement, "wrinkles")}
    # closed and shallow; on the grid axes every face across the stacking axis lies a whole
    # number of layers from the lowest (the layers' 0.1 % overlap aside)
    aligned = [r for r in made if is_axis_aligned(r["seed"])][:3]
    assert aligned
    for recipe in aligned:
        vertices, faces = recipe_mesh(recipe)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        voxel = 1.0 / (recipe["resolution"] - 2)
        layer = recipe["layer_voxels"] * voxel
        extent = np.ptp(vertices, axis=0)
        axis = int(np.argmin(extent))
        assert extent[axis] <= 12 * layer * 1.01 and extent.max() == pytest.approx(1.0, abs=1e-9)
        across = np.abs(mesh.face_normals[:, axis]) > 1 - AXIS_TOL
        heights = (vertices[faces[across]][..., axis].ravel() - vertices[:, axis].min()) / layer
        assert np.abs(heights - np.round(heights)).max() < 0.02
        assert len(np.unique(np.round(heights))) >= 3
    v, _ = layered_shape(made[0]["seed"], 1 / 62, 1 / 62)  # deterministic
    np.testing.assert_array_equal(v, layered_shape(made[0]["seed"], 1 / 62, 1 / 62)[0])
    assert make_sample(made[0])["lattice"].any()


def test_strut_is_a_bar_reaching_its_radius_past_both_ends():
    a, b, radius = np.array([0.1, -0.2, 0.3]), np.array([0.5, 0.4, -0.1]), 0.03
    mesh = trimesh.Trimesh(*_arrays(strut(a, b, radius, 48)), process=False)
    assert mesh.is_watertight and mesh.volume > 0
    axis = (b - a) / np.linalg.norm(b - a)
    along = (mesh.vertices - a) @ axis  # (V,)
    across = np.linalg.norm(mesh.vertices - a - along[:, None] * axis, axis=1)
    length = np.linalg.norm(b - a)
    assert along.min() == pytest.approx(-radius) and along.max() == pytest.approx(length + radius)
    assert np.allclose(across, radius)
    # a 48-gon: the volume of the cylinder within 0.3 %
    assert mesh.volume == pytest.approx(np.pi * radius**2 * (length + 2 * radius), rel=3e-3)
    square = trimesh.Trimesh(*_arrays(strut(a, b, radius, 4)), process=False)
    assert square.volume == pytest.approx(2 * radius**2 * (length + 2 * radius), rel=1e-6)


def _arrays(m):
    mesh = m.to_mesh64()
    return (np.asarray(mesh.vert_properties)[:, :3],
            np.asarray(mesh.tri_verts).astype(np.int64))


def _recipes_of_a_kind(others: dict, field: str, share: float, earlier: tuple) -> list[dict]:
    """The recipes of seeds 0..299 with ``others`` and ``field=share`` that became the kind
    (their ``field`` set), checked against the recipes without it: they are ``share`` of the
    seeds no earlier kind took (recipe keys ``earlier``), every other recipe is unchanged, and
    a made one keeps its draws but the placement, unwrinkled and unturned (its shape function
    places it)."""
    plain = [sample_recipe(s, **others) for s in range(300)]
    changed = [sample_recipe(s, **others, **{field: share}) for s in range(300)]
    made = [b for b in changed if b.get(field)]
    candidates = [a for a in plain if not any(a.get(k) for k in earlier)]
    assert len(made) / len(candidates) == pytest.approx(share, abs=0.08)
    placement = ("family", "rotation", "axis_aligned", "tilt_degrees", field)
    for a, b in zip(plain, changed):
        if not b.get(field):
            assert b == a
            continue
        assert not any(a.get(k) for k in earlier)
        assert "wrinkles" not in b and "tilt_degrees" not in b
        assert b["rotation"] == np.eye(3).tolist()
        assert {k: v for k, v in b.items() if k not in placement} == {
            k: v for k, v in a.items() if k not in (*placement, "wrinkles")}
    return made


def test_strut_recipes_keep_the_other_draws_and_build_frames_of_thin_bars():
    from scipy import ndimage

    from agndc_core.study.shapes import STRUT_RADIUS_VOXELS
    from agndc_core.voxelize import voxelize

    others = dict(wrinkled=0.5, sheets=0.2, tilted=0.3, spikes=0.2, layered=0.2)
    made = _recipes_of_a_kind(others, "struts", 0.3, ("sheet_voxels", "spikes", "layer_voxels"))
    for b in made:
        assert b["family"] == "struts" and b["axis_aligned"] == is_axis_aligned(b["seed"])
    # closed, normalised and thin: no point of the grid lies deeper inside than the slabs a
    # pavilion stands on (half of 5 bar radii), where generate_shape's solids go tens of
    # voxels deep
    def depth(vertices, faces, resolution):  # voxels from the deepest point to the outside
        grid = voxelize(vertices, faces, resolution)
        return ndimage.distance_transform_edt(np.pad(grid.occupancy, 1)).max()

    depths, plain_depths = [], []
    for recipe in made[:6]:
        vertices, faces = recipe_mesh(recipe)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        assert np.ptp(vertices, axis=0).max() == pytest.approx(1.0, abs=1e-9)
        depths.append(depth(vertices, faces, recipe["resolution"]))
        assert 1 <= depths[-1] <= 2.5 * STRUT_RADIUS_VOXELS[1] + 1.5, recipe["seed"]
        plain_depths.append(depth(*generate_shape(recipe["seed"]), recipe["resolution"]))
    assert np.mean(plain_depths) > 2 * np.mean(depths)
    v, _ = strut_shape(made[0]["seed"], 1 / 62)  # deterministic
    np.testing.assert_array_equal(v, strut_shape(made[0]["seed"], 1 / 62)[0])
    for seed in range(12):  # every kind of frame (pavilions, space frames, railings, rings)
        mesh = trimesh.Trimesh(*strut_shape(seed, 1 / 62), process=False)
        assert mesh.is_watertight and mesh.volume > 0, seed
        assert np.ptp(mesh.vertices, axis=0).max() == pytest.approx(1.0, abs=1e-9)
    assert make_sample(made[0])["lattice"].any()


def _round_about_an_axis(vertices, faces) -> float:
    """The area share of faces whose normal is perpendicular to a grid axis but along none:
    the sides of cylinders whose axis is a grid axis."""
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    normals = np.abs(mesh.face_normals)
    side = (normals.min(axis=1) < 1e-6) & (normals.max(axis=1) < 0.99)
    return float(mesh.area_faces[side].sum() / mesh.area)


def test_round_recipes_keep_the_other_draws_and_build_round_features_along_the_axes():
    others = dict(wrinkled=0.5, sheets=0.2, tilted=0.3, spikes=0.2, layered=0.2, struts=0.2)
    made = _recipes_of_a_kind(others, "rounds", 0.3,
                              ("sheet_voxels", "spikes", "layer_voxels", "struts"))
    for b in made:
        assert b["family"] == "round" and b["axis_aligned"] == round_aligned(b["seed"])
    aligned = [s for s in range(40) if round_aligned(s)]
    assert 0.6 < len(aligned) / 40 < 0.9
    round_share, cad_share = [], []
    for seed in aligned[:8]:
        vertices, faces = round_shape(seed, 1 / 62)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0, seed
        assert np.ptp(vertices, axis=0).max() == pytest.approx(1.0, abs=1e-9)
        round_share.append(_round_about_an_axis(vertices, faces))
    for seed in [s for s in range(200) if shape_family(s) == "cad" and is_axis_aligned(s)][:8]:
        cad_share.append(_round_about_an_axis(*generate_shape(seed)))
    # every aligned round part has round sides about a grid axis, more than the CAD family
    assert min(round_share) > 0.05 and np.mean(round_share) > 2 * np.mean(cad_share)
    v, _ = round_shape(made[0]["seed"], 1 / 62)  # deterministic
    np.testing.assert_array_equal(v, round_shape(made[0]["seed"], 1 / 62)[0])
    turned = next(s for s in range(40) if not round_aligned(s))
    assert _round_about_an_axis(*round_shape(turned, 1 / 62)) < 0.05
    assert make_sample(made[0])["lattice"].any()
