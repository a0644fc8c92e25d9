"""The resumable study scripts' shared steps (research/study_runs.sh), with a stand-in for the
agndc command that records how it was called."""

import csv
import os
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import research_script

REPO = Path(__file__).resolve().parents[2]

# writes its arguments and an empty rows.csv where `-o` points, as `agndc eval` would
FAKE_AGNDC = """#!/usr/bin/env bash
echo "$@" >> "$CALLS"
while [[ $# -gt 0 ]]; do
    if [[ $1 == -o ]]; then mkdir -p "$2"; touch "$2/rows.csv"; fi
    shift
done
"""


def _score(tmp_path, *calls: str) -> list[str]:
    runs = tmp_path / "runs"
    for step in (10, 300):
        (runs / "full").mkdir(parents=True, exist_ok=True)
        (runs / "full" / f"step-{step:06d}.safetensors").touch()
    fake = tmp_path / "agndc"
    fake.write_text(FAKE_AGNDC)
    fake.chmod(0o755)
    script = "\n".join([f"set -euo pipefail; cd {REPO}", f"runs={runs}; dev=DEV; common=()",
                        "source research/study_runs.sh", f"agndc={fake}", *calls])
    subprocess.run(["bash", "-c", script], check=True, env={"CALLS": str(tmp_path / "calls"),
                                                            "PATH": "/usr/bin:/bin"})
    calls_file = tmp_path / "calls"
    return calls_file.read_text().splitlines() if calls_file.exists() else []


def test_score_evaluates_every_step_once_and_a_tag_forwards_its_options(tmp_path):
    """both_scores = score as remeshed + score tagged _unfiltered with --no-normal-filter."""
    runs = tmp_path / "runs"
    calls = _score(tmp_path, "both_scores full agndc")
    assert len(calls) == 4
    for step in ("000010", "000300"):
        plain = f"eval DEV --methods agndc --checkpoint " \
                f"agndc={runs}/full/step-{step}.safetensors " \
                f"--res 64 -o {runs}/eval_full_step-{step}"
        assert plain in calls
        assert f"{plain.replace('eval_full_', 'eval_full_unfiltered_')} --no-normal-filter" \
            in calls
    # resumable: a finished evaluation (its rows.csv exists) is not run again
    assert _score(tmp_path, "both_scores full agndc") == calls


def _table_script():
    return research_script("learning_curve_table")


def test_a_continued_run_counts_its_steps_on_from_the_checkpoint_it_started_from(tmp_path):
    """learning_curve_table: a run warm-started from another run's step checkpoint (or its final
    one) is placed after it on the step axis, followed back through chains; a run started from a
    checkpoint outside the runs folder, or from nothing, starts at 0."""
    import json

    table = _table_script()
    runs = tmp_path / "runs"

    def run(name, init=None, steps=(3000, 100, 100)):
        (runs / name).mkdir(parents=True)
        config = {"init": None if init is None else str(init), "steps": list(steps)}
        (runs / name / "run.json").write_text(json.dumps({"config": config}))

    run("long")
    run("cont", runs / "long" / "step-003000.safetensors", steps=(2400, 0, 0))
    run("cont2", runs / "cont" / "final.safetensors", steps=(500, 0, 0))
    run("elsewhere", tmp_path / "shipped" / "step-000700.safetensors")
    assert table.steps_before(runs, "long") == 0
    assert table.steps_before(runs, "cont") == 3000
    assert table.steps_before(runs, "cont_unfiltered") == 3000
    assert table.steps_before(runs, "cont2") == 5400
    assert table.steps_before(runs, "elsewhere") == 0
    assert table.steps_before(runs, "no_such_run") == 0


def test_a_mirrored_pass_maps_back_onto_the_lattice_cells():
    """mirror_border: surface nets (mirror-symmetric) on the mirrored lattice, mapped back,
    gives the same vertex in every cell the surface crosses; cells nearer the high end of the
    occupied box are counted per axis."""
    import numpy as np
    from scipy import ndimage

    from agndc_core.grid import crossed_edges, pad_to_lattice, surface_cells
    from agndc_core.surfacenets import surface_nets_lattice

    mirror = research_script("mirror_border")
    field = ndimage.gaussian_filter(np.random.default_rng(0).random((20, 17, 13)), 2)
    lattice = pad_to_lattice(field > 0.5)
    flipped = np.ascontiguousarray(np.flip(lattice, axis=(0, 1, 2)))
    back = mirror.mirrored_back(surface_nets_lattice(flipped))
    crossed = surface_cells(crossed_edges(lattice))
    assert crossed.sum() > 500
    np.testing.assert_allclose(back[crossed], surface_nets_lattice(lattice)[crossed], atol=1e-6)
    for axes in ((1,), (0, 2)):  # mirrored along some axes only
        flipped = np.ascontiguousarray(np.flip(lattice, axis=axes))
        back = mirror.mirrored_back(surface_nets_lattice(flipped), axes)
        np.testing.assert_allclose(back[crossed], surface_nets_lattice(lattice)[crossed],
                                   atol=1e-6)
    occupied = np.argwhere(lattice)
    for axis, high in enumerate(mirror.nearer_high(lattice)):
        lo, hi = occupied[:, axis].min(), occupied[:, axis].max()
        assert not high[lo] and high[hi - 1]


def test_the_data_mix_counts_each_kind_from_the_samples_recipes(tmp_path):
    """data_mix: shares of family (layered, strut and round parts among them), placement,
    wrinkles and spikes, read back from sample files."""
    import json

    import numpy as np
    import pytest

    from agndc_core.training.data import sample_recipe

    mix = research_script("data_mix")
    made = [sample_recipe(s, wrinkled=1.0, sheets=0.25, tilted=1.0, spikes=0.3, layered=0.2,
                          struts=0.2, rounds=0.15) for s in range(120)]
    for recipe in made:  # only the recipe: what the script reads
        np.savez(tmp_path / f"sample_{recipe['seed']:06d}.npz", recipe=json.dumps(recipe))
    (tmp_path / "other.npz").touch()  # not a sample
    read = mix.recipes(tmp_path)
    assert read == made
    shares = mix.kinds(read)
    sheets = sum(r["family"] == "sheet" for r in made)
    assert shares["sheet"] == pytest.approx(sheets / 120) and 0 < sheets < 60
    assert shares["tilted"] == pytest.approx(sum("tilt_degrees" in r for r in made) / 120)
    assert shares["tilted"] > 0.15 and shares["wrinkled"] > 0.1
    assert shares["spiky"] == pytest.approx(sum(bool(r.get("spikes")) for r in made) / 120)
    assert 0.1 < shares["spiky"] < 0.4
    layered = sum(r["family"] == "layered" for r in made)
    assert shares["layered"] == pytest.approx(layered / 120) and 0 < layered < 60
    struts = sum(r["family"] == "struts" for r in made)
    assert shares["struts"] == pytest.approx(struts / 120) and 0 < struts < 40
    rounds = sum(r["family"] == "round" for r in made)
    assert shares["round"] == pytest.approx(rounds / 120) and 0 < rounds < 40
    assert sum(shares[p] for p in ("aligned", "tilted", "turned")) == pytest.approx(1.0)
    families = [f for f in shares
                if f not in ("aligned", "tilted", "turned", "wrinkled", "spiky")]
    assert sum(shares[f] for f in families) == pytest.approx(1.0)


def test_compared_rows_keep_the_shared_grids_and_count_lower_cds(tmp_path):
    """compare_rows: the reference's method renamed, candidates on the placements all scored,
    the count of grids with a lower CD; read back from rows.csv with empty metrics as nan."""
    import csv
    import math

    compare_rows = research_script("compare_rows")
    columns = ["mesh", "name", "category", "method", "resolution", "shift", "cd", "f1", "nc",
               "ecd", "ef1", "faces", "seconds", "metric_seconds", "error"]

    def row(name, method, cd, shift="0", error=""):
        return {"mesh": f"{name}.obj", "name": name, "category": "CAD", "method": method,
                "resolution": "64", "shift": shift, "cd": str(cd), "f1": "0.5", "nc": "0.9",
                "ecd": "", "ef1": "", "faces": "10", "seconds": "1", "metric_seconds": "1",
                "error": error}

    reference = [row(n, m, cd) for n in ("a", "b", "c")
                 for m, cd in (("mc", 3.0), ("oracle_binary", 1.0), ("agndc", 2.0))]
    reference.append(row("d", "agndc", 2.0, error="failed"))  # an error row is dropped
    candidate = [row("a", "agndc", 1.5), row("b", "agndc", 2.5), row("b", "agndc", 1.0, "1"),
                 row("d", "agndc", 1.0)]
    paths = []
    for name, rows in (("ref", reference), ("new", candidate)):
        path = tmp_path / name / "rows.csv"
        path.parent.mkdir()
        with open(path, "w", newline="") as handle:
            writer = csv.DictWriter(handle, columns)
            writer.writeheader()
            writer.writerows(rows)
        paths.append(path)
    ref_rows = compare_rows.read_rows(paths[0])
    assert len(ref_rows) == 9 and math.isnan(ref_rows[0]["ecd"]) and ref_rows[0]["cd"] == 3.0
    rows, better = compare_rows.compare(ref_rows, {"new": compare_rows.read_rows(paths[1])})
    # only grids a and b (shift 0) were scored by both
    assert better == {"new": (1, 2)}
    assert sorted((r["method"], r["name"]) for r in rows) == sorted(
        [(m, n) for n in ("a", "b") for m in ("mc", "oracle_binary", "reference", "new")])
    assert {r["mesh"] for r in rows} == {"a.obj", "b.obj"}  # one shape counted once
    # the paired difference, shape by shape, on the grids both scored: a -0.5, b +0.5 (b's
    # shift 1 has no reference grid, d's reference is an error row)
    mean, error, shapes = compare_rows.paired_cd(ref_rows, compare_rows.read_rows(paths[1]))
    assert shapes == 2 and mean == pytest.approx(0.0) and error == pytest.approx(0.5)


def test_thin_cells_are_the_surface_cells_of_parts_no_deeper_than_asked():
    """thin_routing: a plate k voxels thick has points ceil(k / 2) deep, so its surface cells
    are thin from that depth on; a thick cube's are not; empty space never is."""
    import numpy as np
    from scipy import ndimage

    from agndc_core.grid import crossed_edges, pad_to_lattice, surface_cells

    routing = research_script("thin_routing")

    def surface(lattice):
        return surface_cells(crossed_edges(lattice))

    for thickness, thin_from in ((2, 1), (4, 2), (6, 3)):
        grid = np.zeros((30, 30, 30), dtype=bool)
        grid[5:25, 5:25, 5:5 + thickness] = True
        lattice = pad_to_lattice(grid)
        cells = surface(lattice)
        for depth in (1, 2, 3):
            thin = routing.thin_cells(lattice, depth, radius=3)
            # never a cell of empty space away from the shape (the search is a cube)
            near = ndimage.binary_dilation(lattice, np.ones((3, 3, 3)), iterations=3 + 1)
            assert thin.any() and not thin[~near].any()
            assert (thin & cells).sum() == (cells.sum() if depth >= thin_from else 0)
    grid = np.zeros((30, 30, 30), dtype=bool)
    grid[5:17, 5:17, 5:17] = True
    assert not routing.thin_cells(pad_to_lattice(grid), 3, radius=3)[surface(
        pad_to_lattice(grid))].any()


def test_flat_terraces_takes_a_recessed_floor_the_network_calls_flat():
    """flat_terraces: a floor one voxel below its rim is a terrace; with flat network
    coordinates it goes to the midpoint (it lies inside the shape's extent) and the rim, the
    outermost layer, keeps its mean; noisy coordinates, pinned cells and (one-sided) the middle
    terraces of a staircase are left alone."""
    import numpy as np

    from agndc_core.flatpatches import pure_splits
    from agndc_core.grid import pad_to_lattice

    script = research_script("flat_terraces")
    grid = np.zeros((30, 30, 30), dtype=bool)
    grid[5:25, 5:25, 5:15] = True
    grid[10:20, 10:20, 14] = False  # a recess one voxel deep
    lattice = pad_to_lattice(grid)
    up = pure_splits(lattice, 2, True)  # (X-1, Y-1, Z-1): faces whose lower corners are inside
    layers = np.flatnonzero(up.any(axis=(0, 1)))
    floor_layer, rim_layer = layers[-2], layers[-1]
    vertex = np.full(lattice.shape + (3,), 0.8)
    out = script.flatten_flat_terraces(lattice, vertex.copy(), np.zeros(vertex.shape, bool),
                                       max_std=0.08, min_cells=16)
    z = out[:-1, :-1, :-1, 2]
    assert np.all(z[up[..., floor_layer].nonzero() + (floor_layer,)] == 0.5)
    np.testing.assert_allclose(z[up[..., rim_layer].nonzero() + (rim_layer,)], 0.8)
    assert up[..., floor_layer].sum() >= 64
    # the step surrounds the floor: it is still taken when the step must enclose it
    enclosed = script.flatten_flat_terraces(lattice, vertex.copy(),
                                            np.zeros(vertex.shape, bool), max_std=0.08,
                                            min_cells=16, one_sided=True, enclosed=0.9)
    np.testing.assert_allclose(enclosed, out)
    # and when the cells along its step must spread both ways (a ring, not a line)
    rounded = script.flatten_flat_terraces(lattice, vertex.copy(),
                                           np.zeros(vertex.shape, bool), max_std=0.08,
                                           min_cells=16, round_steps=0.5)
    np.testing.assert_allclose(rounded, out)
    noisy = vertex + np.random.default_rng(0).normal(0, 0.2, vertex.shape)
    out = script.flatten_flat_terraces(lattice, noisy.copy(), np.zeros(vertex.shape, bool),
                                       max_std=0.08, min_cells=16)
    np.testing.assert_array_equal(out, noisy)
    out = script.flatten_flat_terraces(lattice, vertex.copy(), np.ones(vertex.shape, bool),
                                       max_std=0.08, min_cells=16)
    np.testing.assert_array_equal(out, vertex)
    # a staircase along x: its middle terraces step both ways, its end ones one way
    stairs = np.zeros((40, 20, 20), dtype=bool)
    for step in range(6):
        stairs[5 + 5 * step:10 + 5 * step, 5:15, 5:8 + step] = True
    lattice = pad_to_lattice(stairs)
    vertex = np.full(lattice.shape + (3,), 0.8)
    both = script.flatten_flat_terraces(lattice, vertex.copy(), np.zeros(vertex.shape, bool),
                                        max_std=0.08, min_cells=16)
    one = script.flatten_flat_terraces(lattice, vertex.copy(), np.zeros(vertex.shape, bool),
                                       max_std=0.08, min_cells=16, one_sided=True)
    changed_both = (both[..., 2] == 0.5).sum()
    changed_one = (one[..., 2] == 0.5).sum()
    assert changed_both > changed_one > 0
    # the staircase's end terraces meet a step on one side only: not enclosed
    enclosed = script.flatten_flat_terraces(lattice, vertex.copy(), np.zeros(vertex.shape, bool),
                                            max_std=0.08, min_cells=16, one_sided=True,
                                            enclosed=0.9)
    np.testing.assert_array_equal(enclosed, vertex)
    # each terrace's steps up and its steps down are straight lines: none is round
    rounded = script.flatten_flat_terraces(lattice, vertex.copy(), np.zeros(vertex.shape, bool),
                                           max_std=0.08, min_cells=16, round_steps=0.4)
    np.testing.assert_array_equal(rounded, vertex)


def test_averaged_weights_are_the_mean_of_the_checkpoints(tmp_path):
    """average_weights: the soup of two checkpoints holds each tensor's (weighted) mean and
    names its sources; a soup of one architecture with another is refused."""
    import numpy as np
    import pytest
    import torch

    from agndc_core.checkpoint import read_checkpoint_metadata, read_safetensors, save_checkpoint
    from agndc_core.errors import ModelError
    from agndc_core.nn import AGNDCCascade
    from agndc_core.nn.config import AGNDCConfig

    script = research_script("average_weights")
    config = AGNDCConfig(width=4, band_radius=2)
    paths = []
    for seed in (0, 1):
        torch.manual_seed(seed)
        paths.append(save_checkpoint(AGNDCCascade(config), tmp_path / f"net{seed}",
                                     training={"seed": seed}, metrics={}))
    with torch.no_grad():
        model, metas = script.average_models(paths, [3.0, 1.0])
    out = save_checkpoint(model, tmp_path / "soup", training={}, metrics={})
    a, b, soup = (read_safetensors(p) for p in (*paths, out))
    assert [m["training"]["seed"] for m in metas] == [0, 1]
    differ = [k for k in a if a[k].dtype.kind == "f" and not np.array_equal(a[k], b[k])]
    assert differ
    for key in differ:
        np.testing.assert_allclose(soup[key], 0.75 * a[key] + 0.25 * b[key], atol=1e-6)
    other = save_checkpoint(AGNDCCascade(AGNDCConfig(width=8, band_radius=2)),
                            tmp_path / "wide", training={}, metrics={})
    with pytest.raises(ModelError, match="different architectures"):
        script.average_models([paths[0], other])
    with pytest.raises(ModelError, match="at least two"):
        script.average_models(paths[:1])
    read_checkpoint_metadata(out)


def test_patch_medians_are_each_patchs_median():
    """flat_patch_depth --median: the vectorised per-patch median against np.median per patch;
    an index without cells gets 0."""
    import numpy as np

    script = research_script("flat_patch_depth")
    rng = np.random.default_rng(3)
    patch_of = rng.integers(1, 7, 200)
    patch_of[patch_of == 4] = 5  # patch 4 has no cells
    values = rng.random(200)
    median = script.patch_medians(patch_of, values, 6)
    assert median.shape == (7,) and median[0] == 0 and median[4] == 0
    for p in (1, 2, 3, 5, 6):
        assert median[p] == np.median(values[patch_of == p])


def test_region_parts_of_a_partition_add_up_to_the_chamfer_distance():
    """region_errors: each region takes the ground-truth samples in it and the output samples
    whose nearest ground-truth sample is in it; over a partition the parts sum to the CD."""
    import numpy as np

    script = research_script("region_errors")
    rng = np.random.default_rng(5)
    d_gt, d_out = rng.random(50), rng.random(80)
    nearest = rng.integers(0, 50, 80)
    first = np.arange(50) < 20
    parts = script.region_parts(d_gt, d_out, nearest, {"a": first, "b": ~first})
    assert np.isclose(sum(parts.values()), np.mean(d_gt ** 2) + np.mean(d_out ** 2))
    assert np.isclose(parts["a"], np.sum(d_gt[:20] ** 2) / 50
                      + np.sum(d_out[nearest < 20] ** 2) / 80)


def test_crease_cells_of_a_box_take_both_patches_depths():
    """crease_cells: the cell on a box's edge takes the depth of each face's flattened patch
    along that face's axis; --min-axes 3 takes no edge cell, and a sphere's rims take none
    with --min-axes 2."""
    import numpy as np

    from agndc_core.flatpatches import flatten_patches

    script = research_script("crease_cells")
    lattice = np.zeros((20, 20, 20), dtype=bool)
    lattice[5:15, 5:13, 5:11] = True
    noisy = 0.5 + 0.1 * np.random.default_rng(0).standard_normal(lattice.shape + (3,))
    for min_axes, expected in ((1, True), (2, True), (3, False)):
        pinned = np.zeros(noisy.shape, dtype=bool)
        vertex = flatten_patches(lattice, noisy.copy(), pinned=pinned)
        flat = pinned.copy()
        written = script.carry_to_creases(lattice, vertex, pinned, flat, min_axes=min_axes)
        assert (written > 0) == expected
        # the edge x = 14.x, y = 12.x: x from the +x face's patch (cell (14, 8, 6)), y from
        # the +y face's (cell (10, 12, 6)); z, along the edge, keeps the network's
        edge = vertex[14, 12, 6]
        if expected:
            assert edge[0] == vertex[14, 8, 6, 0] and edge[1] == vertex[10, 12, 6, 1]
            assert pinned[14, 12, 6, :2].all() and not pinned[14, 12, 6, 2]
        else:
            assert np.array_equal(edge, noisy[14, 12, 6])
        assert np.array_equal(vertex[~pinned], noisy[~pinned])  # nothing else moves
    grid = np.indices((24, 24, 24)) - 11.5
    ball = (grid ** 2).sum(axis=0) < 8.2 ** 2
    pinned = np.zeros(ball.shape + (3,), dtype=bool)
    vertex = flatten_patches(ball, np.full(ball.shape + (3,), 0.5), pinned=pinned)
    assert script.carry_to_creases(ball, vertex, pinned, pinned.copy(), min_axes=2) == 0


def test_crease_cells_tell_concave_from_convex_creases():
    """crease_cells --creases: on an L-shaped block the cells along the inner (concave) edge
    are taken with "concave" only, those along an outer (convex) edge with "convex" only."""
    import numpy as np

    from agndc_core.flatpatches import flatten_patches

    script = research_script("crease_cells")
    lattice = np.zeros((24, 16, 24), dtype=bool)
    lattice[4:20, 4:12, 4:9] = True   # the foot
    lattice[4:9, 4:12, 4:20] = True   # the upright
    noisy = 0.5 + 0.1 * np.random.default_rng(1).standard_normal(lattice.shape + (3,))
    inner, outer = (8, 8, 8), (19, 8, 8)  # the concave edge x = 8.x, z = 8.x; the foot's tip
    taken = {}
    for creases in ("concave", "convex"):
        pinned = np.zeros(noisy.shape, dtype=bool)
        vertex = flatten_patches(lattice, noisy.copy(), pinned=pinned)
        flat = pinned.copy()
        script.carry_to_creases(lattice, vertex, pinned, flat, creases=creases)
        taken[creases] = pinned & ~flat
    assert taken["concave"][inner].any() and not taken["convex"][inner].any()
    assert taken["convex"][outer].any() and not taken["concave"][outer].any()


def test_tied_axes_are_those_spanning_the_most_layers():
    import numpy as np

    script = research_script("flat_patch_depth")
    lattice = np.zeros((20, 20, 20), dtype=bool)
    # outer_cell_layers' spans: from the cell layer below the first occupied point layer to
    # the last: x and y 12, z 5
    lattice[3:15, 3:15, 5:10] = True
    assert script.tied(lattice, 12) and not script.tied(lattice, 5)
    lattice[3:16, 3:15, 5:10] = True  # x alone is the longest (13)
    assert not script.tied(lattice, 13) and not script.tied(lattice, 12)


def test_planar_faces_finds_a_tilted_boxs_planes_and_scores_its_own_surface_flat():
    """planar_faces: a box turned 3° has six tilted planes; the box itself measured against
    its samples is flat and on them (0°, RMS 0); a copy with its vertices moved off the planes
    is not."""
    import numpy as np
    import trimesh

    script = research_script("planar_faces")
    box = trimesh.creation.box([1.0, 0.8, 0.5])
    box = box.subdivide().subdivide().subdivide()
    axis = np.array([1.0, 0.6, 0.35]) / np.linalg.norm([1.0, 0.6, 0.35])
    box.apply_transform(trimesh.transformations.rotation_matrix(np.radians(3.0), axis))
    voxel = 1.0 / 62
    region, normals, offsets = script.planes_of(box, 1.0, 40 * voxel ** 2)
    assert len(normals) == 6 and (region >= 0).all()
    assert {script.plane_class(n) for n in normals} == {"tilted"}
    points, index = trimesh.sample.sample_surface(box, 30000, seed=0)
    rows = script.flatness(box.vertices, box.faces, points, region[index], normals, offsets,
                           voxel, 2.0)
    assert len(rows) == 6
    assert all(r["normal_deg"] < 1e-3 and r["rms_vx"] < 1e-6 for r in rows)
    bumpy = box.vertices + 0.2 * voxel * np.random.default_rng(0).standard_normal(
        box.vertices.shape)
    rows = script.flatness(bumpy, box.faces, points, region[index], normals, offsets, voxel, 2.0)
    assert all(r["normal_deg"] > 1.0 and r["rms_vx"] > 0.05 for r in rows)
    # a finely tessellated cylinder's side joins up within 1° but is no plane; its caps are
    tube = trimesh.creation.cylinder(radius=0.3, height=1.0, sections=720)
    assert len(script.planes_of(tube, 1.0, 40 * voxel ** 2)[1]) == 3
    assert len(script.planes_of(tube, 1.0, 40 * voxel ** 2, 0.02 * voxel)[1]) == 2


def test_plane_regions_put_a_bumpy_tilted_face_on_its_plane_and_keep_the_rims():
    """plane_regions: a box turned 5° with its vertices jittered off its faces: the interior
    vertices of each face go onto one plane, the vertices on its edges stay; an axis-aligned
    box is the flat-patch stage's and is left as it is."""
    import numpy as np
    import trimesh

    script = research_script("plane_regions")
    box = trimesh.creation.box([20.0, 16.0, 10.0]).subdivide().subdivide().subdivide()
    for turn, moved in ((5.0, True), (0.0, False)):
        mesh = box.copy()
        axis = np.array([1.0, 0.6, 0.35])
        mesh.apply_transform(trimesh.transformations.rotation_matrix(np.radians(turn), axis))
        bumpy = mesh.vertices + 0.01 * np.random.default_rng(0).standard_normal(
            mesh.vertices.shape)
        out = script.snap_planar_regions(bumpy, mesh.faces)
        on_edge = (np.abs(np.abs(box.vertices) - [10.0, 8.0, 5.0]) < 1e-9).sum(axis=1) >= 2
        assert np.array_equal(out[on_edge], bumpy[on_edge])
        if not moved:
            assert np.array_equal(out, bumpy)
            continue
        # each face's interior vertices lie on one plane (their own least-squares plane)
        for k, half in enumerate((10.0, 8.0, 5.0)):
            face = (np.abs(box.vertices[:, k] - half) < 1e-9) & ~on_edge

            def off_plane(points):
                centred = points - points.mean(axis=0)
                return np.linalg.svd(centred, full_matrices=False)[1][2] / np.sqrt(len(points))

            assert off_plane(out[face]) < 1e-9 < 1e-3 < off_plane(bumpy[face])


def test_spike_rows_are_closed_rows_of_sharp_cones_as_thin_as_asked():
    """spike_rows: a closed slab with one sharp tip per cone; thinner cones when asked; the
    same shape for the same seed."""
    import numpy as np
    import trimesh

    script = research_script("spike_rows")
    for seed in (0, 2):  # seed 2 is turned
        vertices, faces = script.spike_row(seed)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        assert abs(np.ptp(vertices, axis=0).max() - 1.0) < 1e-12
        tips = mesh.vertex_defects > np.pi  # a cone's apex; the slab's corners have pi / 2
        assert 3 <= tips.sum() <= 8
        np.testing.assert_array_equal(vertices, script.spike_row(seed)[0])
    thick = trimesh.Trimesh(*script.spike_row(0), process=False)
    thin = trimesh.Trimesh(*script.spike_row(0, radius=(0.8, 2.0)), process=False)
    assert thin.volume < thick.volume


def test_layered_caps_are_closed_and_their_flat_faces_lie_whole_layers_apart():
    """layered_caps: a closed shallow cap; on the grid axes every face across its thin axis
    lies a whole number of layers from the next; some caps upside down (the skirt, the widest
    layer, on top); thinner layers when asked; the same shape for the same seed."""
    import numpy as np
    import trimesh

    script = research_script("layered_caps")
    skirt_side = []
    for seed in (0, 1, 3, 4, 6, 7, 9, 10):  # every third seed (2, 5, ...) is turned
        vertices, faces = script.layered_cap(seed)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        extent = np.ptp(vertices, axis=0)
        assert abs(extent.max() - 1.0) < 1e-12 and extent[2] < 0.35
        np.testing.assert_array_equal(vertices, script.layered_cap(seed)[0])
        across = np.abs(mesh.face_normals[:, 2]) > 1 - 1e-9
        levels = np.unique(np.round(vertices[faces[across]][..., 2].ravel(), 9))
        steps = np.diff(levels)
        layer = steps.min()
        assert 0.8 * script.VOXEL < layer < 1.35 * script.VOXEL and len(levels) >= 4
        assert np.abs(steps / layer - np.round(steps / layer)).max() < 1e-6
        radius = np.linalg.norm(vertices[:, :2], axis=1)
        skirt_side.append(np.sign(vertices[radius > radius.max() - 1e-6, 2].mean()))
    assert set(skirt_side) == {-1.0, 1.0}
    thin = script.layered_cap(0, layer=(0.5, 0.51))[0]
    assert np.ptp(thin[:, 2]) < np.ptp(script.layered_cap(0)[0][:, 2])


@pytest.mark.slow
def test_a_set_scored_in_shards_gives_the_rows_of_one_eval(tmp_path):
    """research/score_validation_parallel.sh: shards made from their own first seeds are the
    set's shapes, and their merged rows are those of one `agndc eval` of the whole set."""
    python = sys.executable
    env = {**os.environ, "AGNDC_PYTHON": python, "AGNDC_SET_SIZE": "2"}
    script = REPO / "research" / "score_validation_parallel.sh"
    subprocess.run(["bash", str(script), "sheets", tmp_path / "val", tmp_path / "out", "2"],
                   check=True, env=env, capture_output=True)
    cli = [python, "-m", "agndc_core.cli"]
    subprocess.run([*cli, "val-data", "--sheets", "-o", tmp_path / "whole", "-n", "2",
                    "--workers", "1"], check=True, capture_output=True, cwd=REPO)
    subprocess.run([*cli, "eval", tmp_path / "whole", "--res", "64", "--methods",
                    "mc,oracle_binary,agndc", "--samples", "30000", "-o", tmp_path / "one"],
                   check=True, capture_output=True, cwd=REPO)

    def rows(path):
        with open(path) as f:
            return [(r["name"], r["category"], r["method"], r["cd"], r["ef1"])
                    for r in csv.DictReader(f)]

    sharded = rows(tmp_path / "out" / "sheets" / "shipped" / "rows.csv")
    assert len(sharded) == 6 and sharded == rows(tmp_path / "one" / "rows.csv")
    # a checkpoint against that reference: its comparison is printed and written
    weights = REPO / "agndc_core" / "weights" / "agndc.safetensors"
    done = subprocess.run(["bash", str(script), "sheets", tmp_path / "val", tmp_path / "out", "2",
                           weights], check=True, env=env, capture_output=True, text=True)
    assert "CD below the reference's on 0 of 2 grids" in done.stdout
    assert (tmp_path / "out" / "sheets" / "agndc.md").read_text() == done.stdout


def test_round_strips_are_a_thin_cylinders_sides_not_a_boxs_faces():
    import numpy as np
    from scipy import ndimage

    from agndc_core.flatpatches import _IN_PLANE, _pure_splits_last
    from agndc_core.grid import pad_to_lattice

    script = research_script("round_strips")

    def round_patches(occupancy):
        lattice = pad_to_lattice(occupancy)
        found = []
        for axis in range(3):
            points = np.moveaxis(lattice, axis, -1)
            for lower_inside in (True, False):
                split = _pure_splits_last(points, lower_inside)
                patches, count = ndimage.label(split, _IN_PLANE)
                found.append(script.round_strip_patches(points, lower_inside, split, patches,
                                                        count, 8, 0.5)[1:])
        return found

    box = np.zeros((20, 16, 30), dtype=bool)
    box[3:9, 4:12, 2:27] = True  # a bar 6 x 8 voxels across: its faces are narrow, and flat
    assert not any(r.any() for r in round_patches(box))
    x, y = np.mgrid[:20, :20] - 9.5
    disc = x ** 2 + y ** 2 <= 5.2 ** 2
    rod = np.zeros((20, 20, 30), dtype=bool)
    rod[disc] = True
    rod[..., :2] = rod[..., -2:] = False  # a rod of radius ~5 along z, capped
    found = round_patches(rod)
    # the four sides facing x and y are round strips; the caps (z) are flat
    assert all(r.any() for r in found[:4]) and not found[4].any() and not found[5].any()


def test_quadratic_round_patches_find_bowed_depths_not_noisy_flat_ones():
    import numpy as np

    script = research_script("round_strips")
    rng = np.random.default_rng(3)
    u, v = np.mgrid[:5, :40]  # two strips 5 cells wide, 40 long, patches 1 and 2
    cells = (np.concatenate([u.ravel(), u.ravel() + 10]), np.concatenate([v.ravel()] * 2),
             np.zeros(400, dtype=int))
    patch_of = np.repeat([1, 2], 200)
    across = u.ravel() - 2.0
    bowed = 0.6 - 0.1 * across ** 2  # sags 0.4 voxel at its edges, like a cylinder's cap strip
    flat = 0.5 + rng.normal(0, 0.1, 200)  # the network's noise about a flat face
    depth = np.concatenate([bowed, flat])
    found = script.quadratic_round_patches(cells, depth, patch_of, 2, 20, 0.1, 0.9)
    assert found.tolist() == [False, True, False]
    # too few cells for the rule: neither
    assert not script.quadratic_round_patches(cells, depth, patch_of, 2, 201, 0.1, 0.9).any()


def test_pin_plates_are_closed_and_their_round_sides_stand_along_the_axes():
    """axis_pins: a closed plate with round pins (and a shaft on odd seeds) whose sides stand
    along the grid axes; the same shape for the same seed."""
    import numpy as np
    import trimesh

    script = research_script("axis_pins")
    for seed in (0, 1):
        vertices, faces = script.pin_plate(seed)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        assert abs(np.ptp(vertices, axis=0).max() - 1.0) < 1e-12
        normals = mesh.face_normals
        # round sides: faces whose normal is off every axis but square to one of them
        round_side = (np.abs(normals).max(axis=1) < 0.99) & (np.abs(normals).min(axis=1) < 1e-6)
        assert round_side.sum() > 100
        assert (np.abs(normals).min(axis=1) < 1e-6).all()  # nothing tilted off the axes
        np.testing.assert_array_equal(vertices, script.pin_plate(seed)[0])
