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
    filtered_normals,
    keep_orientation,
    normal_spread,
    wrinkled_surface,
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
        planar = np.random.default_rng(3).random(len(vertices)) < 0.05
        np.testing.assert_allclose(filter_mesh(vertices, tris, params, fixed, planar_v=planar),
                                   filter_mesh_naive(vertices, tris, params, fixed, planar),
                                   atol=1e-12)


def _strip_normals(tilted_face: int, degrees: float) -> np.ndarray:
    """(10, 3) normals of a 10-face strip: all +z but one, tilted by ``degrees`` about x."""
    normals = np.tile([0.0, 0.0, 1.0], (10, 1))
    angle = np.radians(degrees)
    normals[tilted_face] = [0.0, -np.sin(angle), np.cos(angle)]
    return normals


def test_vertex_passes_lighten_detail_away_from_planes_and_creases():
    """A strip of triangles [v, v+1, v+2]: vertex v shares a face with v +- 1 and v +- 2. Face 4
    tilted 10 degrees bends the normals at its vertices 4-6 (6.7 degrees from their mean): with
    their ring, vertices 2-8 are detail; the planar vertex 8 and its ring (6-10) keep all
    passes. Tilted 90 degrees, face 4 makes a crease: no vertex is lightened."""
    from agndc_core.normalfilter import vertex_faces, vertex_passes

    faces = np.array([[v, v + 1, v + 2] for v in range(10)])
    incidence = vertex_faces(faces, 12)
    planar = np.zeros(12, dtype=bool)
    planar[8] = True
    params = NormalFilter(vertex_iterations=7, detail_vertex_iterations=2, detail_degrees=5.0,
                          detail_rings=1, crease_degrees=30.0, planar_rings=1)
    expected = np.full(12, 7)
    expected[[2, 3, 4, 5]] = 2
    np.testing.assert_array_equal(
        vertex_passes(faces, incidence, _strip_normals(4, 10.0), planar, params), expected)
    np.testing.assert_array_equal(
        vertex_passes(faces, incidence, _strip_normals(4, 90.0), planar, params), 7)
    flat = _strip_normals(4, 0.0)  # no bend, no detail
    np.testing.assert_array_equal(vertex_passes(faces, incidence, flat, planar, params), 7)


def _wrinkled_sphere(subdivisions=4):
    """An icosphere of radius 1 with wrinkles along its normals: waves ~0.5 long and up to
    0.03 high, a few cells long on a mesh of edges ~0.08 (detail, not noise)."""
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions)
    v = np.asarray(sphere.vertices)
    wave = 0.03 * np.sin(12 * v[:, 0]) * np.sin(12 * v[:, 1])
    return v * (1 + wave)[:, None], np.asarray(sphere.faces)


def test_detail_takes_the_lighter_update():
    """On a wrinkled sphere (no planar vertex) the filter keeps more of the wrinkles than the
    full update does; with every vertex planar, or no angle counting as detail, it is the
    full update."""
    wrinkled, faces = _wrinkled_sphere()
    none, every = np.zeros(len(wrinkled), dtype=bool), np.ones(len(wrinkled), dtype=bool)
    full = filter_mesh(wrinkled, faces)
    np.testing.assert_array_equal(filter_mesh(wrinkled, faces, planar_v=every), full)
    never = NormalFilter(detail_degrees=90.0)
    np.testing.assert_array_equal(filter_mesh(wrinkled, faces, never, planar_v=none),
                                  filter_mesh(wrinkled, faces, never))
    light = filter_mesh(wrinkled, faces, planar_v=none)
    lost = [float(np.sqrt(np.mean(np.sum((out - wrinkled) ** 2, axis=1))))
            for out in (full, light)]  # RMS of what the filter took
    assert lost[1] < 0.85 * lost[0]


def _ellipsoid(subdivisions, semi_axes):
    """An icosphere scaled to an ellipsoid, in lattice units (edges ~1.2-1.5 long below)."""
    sphere = trimesh.creation.icosphere(subdivisions)
    return (np.asarray(sphere.vertices) * np.asarray(semi_axes, dtype=np.float64),
            np.asarray(sphere.faces))


def _spread(vertices, faces, params=None):
    params = params or NormalFilter()
    _, incidence, normals = filtered_normals(vertices, faces, params)
    return normal_spread(faces, incidence, normals)


def test_a_wrinkled_surface_is_one_with_few_planar_vertices_and_a_middle_share_on_detail():
    params = NormalFilter()
    # an ellipsoid bent at the scale of a few cells over ~65 % of its vertices: in the band
    bent, faces = _ellipsoid(3, (8, 8, 16))
    spread = _spread(bent, faces)
    assert 0.5 < np.mean(spread > params.detail_degrees) < 0.8
    none = np.zeros(len(bent), dtype=bool)
    assert wrinkled_surface(spread, none, params)
    # 10 % of its vertices on planar patches (a part, not a scan), or a narrower band: filtered
    some = np.arange(len(bent)) < 0.1 * len(bent)
    assert not wrinkled_surface(spread, some, params)
    assert not wrinkled_surface(spread, none, NormalFilter(wrinkled_detail_share=(0.8, 0.9)))
    # a large sphere (nothing on detail) and a small one (everything, like a knot's tube)
    for semi_axes, subdivisions in (((20, 20, 20), 4), ((4, 4, 4), 2)):
        ball, ball_faces = _ellipsoid(subdivisions, semi_axes)
        assert not wrinkled_surface(_spread(ball, ball_faces), np.zeros(len(ball), bool), params)
    assert not wrinkled_surface(np.zeros(0), np.zeros(0, dtype=bool), params)


def test_a_wrinkled_surface_keeps_the_networks_vertices():
    bent, faces = _ellipsoid(3, (8, 8, 16))
    noisy = bent + np.random.default_rng(4).normal(0.0, 0.1, bent.shape)
    none = np.zeros(len(bent), dtype=bool)
    assert wrinkled_surface(_spread(noisy, faces), none)
    for run in (filter_mesh, filter_mesh_naive):
        np.testing.assert_array_equal(run(noisy, faces, planar_v=none), noisy)
        # without planar vertices to read (planar_v None) the filter does not judge: it filters
        assert not np.allclose(run(noisy, faces), noisy)
    some = np.arange(len(bent)) < 0.1 * len(bent)
    filtered = filter_mesh(noisy, faces, planar_v=some)
    assert not np.allclose(filtered, noisy)
    np.testing.assert_allclose(filtered, filter_mesh_naive(noisy, faces, planar_v=some),
                               atol=1e-12)


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
