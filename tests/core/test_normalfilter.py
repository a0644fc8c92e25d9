"""Bilateral normal filtering (agndc_core/normalfilter.py): the vectorised filter against the
naive reference, and the invariants it promises: noise off faces goes down, creases and corners
stay where they are, no face turns over, the topology is untouched."""

import numpy as np
import pytest
import trimesh

from agndc_core.grid import VoxelGrid
from agndc_core.meshcheck import topology_violations
from agndc_core.normalfilter import (
    NormalFilter,
    face_geometry,
    filter_mesh,
    filter_mesh_naive,
    keep_orientation,
)
from agndc_core.pipeline import remesh, taubin_smooth

NOISE = 0.01  # of a unit box tessellated into faces of 1/8: a network's noise in voxel terms


def _noisy_box(seed=0, subdivisions=3):
    """A unit box tessellated into 8 x 8 quads per side (768 triangles), every vertex jittered
    by Gaussian noise of std NOISE; returns (clean vertices, noisy vertices, faces)."""
    mesh = trimesh.creation.box((1.0, 1.0, 1.0))
    for _ in range(subdivisions):
        mesh = mesh.subdivide()
    clean = np.asarray(mesh.vertices, dtype=np.float64)
    noisy = clean + np.random.default_rng(seed).normal(0.0, NOISE, clean.shape)
    return clean, noisy, np.asarray(mesh.faces, dtype=np.int64)


def _off_face_rms(vertices):
    """RMS distance of the vertices to the box's nearest face plane."""
    return float(np.sqrt(np.mean((0.5 - np.abs(vertices).max(axis=1)) ** 2)))


def _corner_error(vertices, clean):
    """Largest distance of the 8 corner vertices from the true corners."""
    corners = np.all(np.isclose(np.abs(clean), 0.5), axis=1)
    assert corners.sum() == 8
    return float(np.linalg.norm(vertices[corners] - clean[corners], axis=1).max())


@pytest.mark.parametrize("params", [NormalFilter(), NormalFilter(0.5, 2, 3)])
def test_filter_matches_the_naive_reference(params):
    _, noisy, faces = _noisy_box(subdivisions=2)
    sphere = trimesh.creation.icosphere(subdivisions=2)
    bumpy = sphere.vertices * (1 + 0.05 * np.random.default_rng(1).normal(
        size=(len(sphere.vertices), 1)))
    for vertices, tris in ((noisy, faces), (bumpy, sphere.faces)):
        np.testing.assert_allclose(filter_mesh(vertices, tris, params),
                                   filter_mesh_naive(vertices, tris, params), atol=1e-12)
        fixed = np.random.default_rng(2).random(vertices.shape) < 0.3
        out = filter_mesh(vertices, tris, params, fixed)
        np.testing.assert_allclose(out, filter_mesh_naive(vertices, tris, params, fixed),
                                   atol=1e-12)
        np.testing.assert_array_equal(out[fixed], vertices[fixed])
        assert not np.allclose(out[~fixed], vertices[~fixed])


def test_faces_flatten_while_corners_stay():
    clean, noisy, faces = _noisy_box()
    filtered = filter_mesh(noisy, faces)
    # the noise across the faces drops to well under half
    assert _off_face_rms(filtered) < 0.4 * _off_face_rms(noisy)
    # the corners do not round off: they stay about as near their true place as the noise put
    # them, where Taubin smoothing, which removes the same noise, pulls them inward
    corner = _corner_error(filtered, clean)
    assert corner < 3 * NOISE
    assert corner < 0.5 * _corner_error(taubin_smooth(noisy, faces), clean)


def test_an_exact_box_is_left_where_it_is():
    clean, _, faces = _noisy_box()
    # faces across an edge (90 degrees) get weight exp(-2 / (2 * 0.3²)) ~ 1.5e-5
    np.testing.assert_allclose(filter_mesh(clean, faces), clean, atol=1e-4)


def test_no_face_turns_over():
    """A sliver beside a crease, jittered hard: the vertex update alone would fold some faces
    over; ``keep_orientation`` puts their vertices back, so no face points against its original
    normal, and the faces (the topology) are the ones given."""
    clean, noisy, faces = _noisy_box(seed=3, subdivisions=4)
    noisy = clean + np.random.default_rng(3).normal(0.0, 0.03, clean.shape)
    original = face_geometry(noisy, faces)[0]
    filtered = filter_mesh(noisy, faces, NormalFilter(0.6, 8, 20))
    turned = np.sum(face_geometry(filtered, faces)[0] * original, axis=1) < 0
    assert not turned.any()
    assert np.isfinite(filtered).all()


def test_keep_orientation_puts_back_only_what_folds():
    vertices = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=np.float64)
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    original = face_geometry(vertices, faces)[0]
    moved = vertices.copy()
    moved[3] = [-0.5, -0.5, 0.0]  # folds face 1 over; face 0 does not use vertex 3
    kept = keep_orientation(vertices, moved, faces, original)
    np.testing.assert_array_equal(kept[3], vertices[3])
    fine = vertices + [0.0, 0.0, 0.1]  # a move that folds nothing is kept whole
    np.testing.assert_array_equal(keep_orientation(vertices, fine, faces, original), fine)


def test_degenerate_input():
    vertices = np.random.default_rng(0).normal(size=(5, 3))
    np.testing.assert_array_equal(filter_mesh(vertices, np.zeros((0, 3), dtype=np.int64)),
                                  vertices)
    # a zero-area face (two equal corners) beside a real one: no NaN, the lone vertex 4 stays
    vertices[2] = vertices[1]
    faces = np.array([[0, 1, 2], [0, 1, 3]])
    out = filter_mesh(vertices, faces)
    assert np.isfinite(out).all()
    np.testing.assert_array_equal(out[4], vertices[4])


def test_remesh_filters_a_networks_mesh_only():
    """The filter runs on the learned methods' meshes (a closed, outward 2-manifold stays one,
    the faces are those contouring gave), is skipped with ``normal_filter=False``, and never
    touches the classical methods."""
    occupancy = np.zeros((18, 18, 18), dtype=bool)
    x, y, z = np.indices(occupancy.shape) - 8.5
    occupancy[x ** 2 + y ** 2 + z ** 2 < 6.3 ** 2] = True
    grid = VoxelGrid(occupancy)
    raw = remesh(grid, method="agndc", threads=1, normal_filter=False)
    filtered = remesh(grid, method="agndc", threads=1)
    assert "normal filter" in filtered.timings and "normal filter" not in raw.timings
    np.testing.assert_array_equal(filtered.faces, raw.faces)
    assert not np.array_equal(filtered.vertices, raw.vertices)
    assert not any(topology_violations(filtered.vertices, filtered.faces).values())
    # still outward: the signed volume is the raw mesh's to within the noise removed
    volume = [trimesh.Trimesh(r.vertices, r.faces, process=False).volume for r in (raw, filtered)]
    assert volume[1] > 0 and abs(volume[1] / volume[0] - 1) < 0.02
    nets = remesh(grid, method="surfacenets", normal_filter=True)
    assert "normal filter" not in nets.timings


def test_the_filter_checks_before_every_pass():
    """A cancel reaches inside the filter: ``check`` runs before each of its passes."""
    from agndc_core.errors import CancelledError
    from agndc_core.normalfilter import DEFAULT, filter_mesh

    _, vertices, faces = _noisy_box()
    calls = []
    filter_mesh(vertices, faces, check=lambda: calls.append(1))
    assert len(calls) == DEFAULT.normal_iterations + DEFAULT.vertex_iterations

    def cancel_on_third():
        calls.append(1)
        if len(calls) > 2:
            raise CancelledError("cancelled")

    calls.clear()
    with pytest.raises(CancelledError):
        filter_mesh(vertices, faces, check=cancel_on_third)
    assert len(calls) == 3
