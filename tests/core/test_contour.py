"""Dual contouring: exact agreement with the naive reference, and geometric invariants."""

import numpy as np
import pytest
import trimesh

from agndc_core.contour import drop_small_components, dual_contour
from agndc_core.contour_naive import dual_contour_naive
from agndc_core.grid import pad_to_lattice
from agndc_core.labels import crossed_edges

from conftest import edge_use_counts


def random_blobs(shape, seed, fill=0.3):
    rng = np.random.default_rng(seed)
    return rng.random(shape) < fill


@pytest.mark.parametrize("seed", range(4))
def test_vectorised_equals_naive(seed):
    lattice = pad_to_lattice(random_blobs((9, 7, 10), seed))
    rng = np.random.default_rng(seed)
    vertex = rng.random(lattice.shape + (3,)).astype(np.float32)
    edge = crossed_edges(lattice)
    fast = dual_contour(vertex, edge, lattice)
    slow = dual_contour_naive(vertex, edge, lattice)
    assert np.array_equal(fast[1], slow[1])  # topology: exact
    np.testing.assert_allclose(fast[0], slow[0], atol=0, rtol=0)


def test_predicted_edges_without_orientation_equal_naive():
    rng = np.random.default_rng(5)
    edge = rng.random((8, 8, 8, 3)) < 0.1
    vertex = rng.random((8, 8, 8, 3))
    fast = dual_contour(vertex, edge, None)
    slow = dual_contour_naive(vertex, edge, None)
    assert np.array_equal(fast[1], slow[1]) and np.array_equal(fast[0], slow[0])


def test_single_voxel_is_an_outward_octahedron():
    lattice = pad_to_lattice(np.ones((1, 1, 1), bool))
    vertex = np.full(lattice.shape + (3,), 0.5)
    vertices, faces = dual_contour(vertex, crossed_edges(lattice), lattice)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert len(vertices) == 8 and len(faces) == 12  # 6 quads around the voxel's 6 edges
    assert mesh.is_watertight and mesh.volume > 0
    assert mesh.euler_number == 2


def test_solid_block_is_closed_outward_and_euler_two():
    lattice = pad_to_lattice(np.ones((5, 3, 4), bool))
    vertex = np.full(lattice.shape + (3,), 0.5)
    vertices, faces = dual_contour(vertex, crossed_edges(lattice), lattice)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert np.all(edge_use_counts(faces) == 2)
    assert mesh.is_winding_consistent and mesh.volume > 0 and mesh.euler_number == 2
    # dual vertices at cell centres: the surface lies half a voxel outside the voxel centres
    assert np.isclose(mesh.volume, 5 * 3 * 4)


def test_empty_input_gives_empty_arrays():
    vertices, faces = dual_contour(np.zeros((4, 4, 4, 3)), np.zeros((4, 4, 4, 3), bool))
    assert vertices.shape == (0, 3) and faces.shape == (0, 3) and faces.dtype == np.int64


def test_drop_small_components_and_merge():
    occupancy = np.zeros((12, 6, 6), bool)
    occupancy[1:5, 1:5, 1:5] = True  # big block
    occupancy[9, 2, 2] = True  # single voxel: 12 faces
    lattice = pad_to_lattice(occupancy)
    vertex = np.full(lattice.shape + (3,), 0.5)
    vertices, faces = dual_contour(vertex, crossed_edges(lattice), lattice,
                                   min_component_faces=13)
    assert len(faces) == 2 * 6 * 4 * 4  # only the 4x4x4 block is left: 16 quads per side
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.body_count == 1 and mesh.is_watertight
    vertex[:] = 0.0  # clipped vertices collapse onto shared corners
    merged = dual_contour(vertex, crossed_edges(lattice), lattice, merge_vertices=True)
    assert len(merged[0]) <= len(vertices) + 8


def test_drop_small_components_reindexes():
    vertices = np.arange(18, dtype=float).reshape(6, 3)
    faces = np.array([[0, 1, 2], [3, 4, 5], [3, 5, 4]])
    kept_vertices, kept_faces = drop_small_components(vertices, faces, 2)
    assert np.array_equal(kept_vertices, vertices[3:]) and kept_faces.max() == 2
