"""Tests of agndc_core.shapes: validity, normalisation, determinism and diversity."""

import numpy as np
import pytest
import trimesh

from agndc_core.shapes import generate_dataset, generate_shape

SEEDS = range(20)
#: a face normal counts as axis-aligned when its largest component is within this of 1
AXIS_TOL = 1e-6


@pytest.fixture(scope="module")
def meshes():
    """seed -> trimesh.Trimesh (unprocessed, so the generator's arrays are tested as-is)."""
    return {seed: trimesh.Trimesh(*generate_shape(seed), process=False) for seed in SEEDS}


@pytest.mark.parametrize("seed", SEEDS)
def test_watertight_normalised_solid(meshes, seed):
    mesh = meshes[seed]
    assert mesh.vertices.dtype == np.float64 and mesh.faces.dtype == np.int64
    assert len(mesh.faces) >= 12
    assert mesh.is_watertight and mesh.is_volume
    assert mesh.volume > 0
    lo, hi = mesh.bounds
    assert (hi - lo).max() == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose((lo + hi) / 2, 0.0, atol=1e-9)


def test_deterministic_and_seed_dependent():
    v1, f1 = generate_shape(7)
    v2, f2 = generate_shape(7)
    np.testing.assert_array_equal(v1, v2)
    np.testing.assert_array_equal(f1, f2)
    v3, f3 = generate_shape(8)
    assert v1.shape != v3.shape or not np.array_equal(v1, v3)


def test_diversity(meshes):
    ms = list(meshes.values())
    n_comp = [len(m.split(only_watertight=False)) for m in ms]
    # genus summed over components from the Euler characteristic: chi = sum(2 - 2 g_i)
    genus = [(2 * c - m.euler_number) // 2 for m, c in zip(ms, n_comp)]
    assert sum(g > 0 for g in genus) >= 3  # through-holes, tubes
    assert sum(c > 1 for c in n_comp) >= 1  # several disjoint parts
    # share of the surface area whose normal is a grid axis: 0 for a freely rotated shape,
    # most of it for one left on the axes (cylinders and chamfers keep it below 1)
    on_grid = [m.area_faces[np.abs(m.face_normals).max(axis=1) > 1 - AXIS_TOL].sum() / m.area
               for m in ms]
    assert sum(f == 0 for f in on_grid) >= 10  # freely rotated shapes
    assert sum(f > 0.5 for f in on_grid) >= 2  # and some left on the grid axes
    assert len({len(m.faces) for m in ms}) >= 15  # not the same few templates


def test_generate_dataset_matches_generate_shape():
    rows = list(generate_dataset(2, seed0=5))
    assert [r[0] for r in rows] == [5, 6]
    np.testing.assert_array_equal(rows[1][1], generate_shape(6)[0])
