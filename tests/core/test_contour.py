"""Dual contouring: exact agreement with the naive reference, and geometric invariants."""

import numpy as np
import pytest
import trimesh

from agndc_core.contour import ContourError, drop_small_components, dual_contour
from agndc_core.contour_naive import dual_contour_naive
from agndc_core.grid import pad_to_lattice
from agndc_core.labels import crossed_edges
from agndc_core.surfacenets import surface_nets_cells, surface_nets_lattice
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


def test_dense_grids_with_patches_and_tubes_equal_naive():
    """Dense random grids hit multi-patch cells and tube faces; fast and naive agree exactly."""
    rng = np.random.default_rng(11)
    tubes = 0
    for _ in range(30):
        lattice = np.pad(rng.random(rng.integers(2, 7, size=3)) < rng.uniform(0.3, 0.9), 1)
        vertex = rng.random(lattice.shape + (3,)).astype(np.float32)
        edge = crossed_edges(lattice)
        fast = dual_contour(vertex, edge, lattice)
        slow = dual_contour_naive(vertex, edge, lattice)
        assert np.array_equal(fast[1], slow[1])
        np.testing.assert_array_equal(fast[0], slow[0])
        tubes += len(fast[1]) - 2 * int(edge.sum())  # each tube vertex adds one triangle
    assert tubes > 0


def test_a_field_given_as_a_function_of_the_cells_contours_the_same():
    """The fold check contours surface nets computed at the contoured cells only."""
    rng = np.random.default_rng(4)
    for _ in range(10):
        lattice = np.pad(rng.random(rng.integers(3, 9, size=3)) < rng.uniform(0.3, 0.8), 1)
        edge = crossed_edges(lattice)
        for inside in (lattice, None):
            dense = dual_contour(surface_nets_lattice(lattice), edge, inside)
            sparse = dual_contour(lambda cells, lat=lattice: surface_nets_cells(lat, cells),
                                  edge, inside)
            assert np.array_equal(dense[1], sparse[1])
            np.testing.assert_array_equal(dense[0], sparse[0])


def test_edges_must_be_the_crossing_parity_of_inside():
    lattice = pad_to_lattice(np.ones((2, 2, 2), bool))
    edge = crossed_edges(lattice)
    edge[0, 0, 0, 0] = True
    with pytest.raises(ContourError, match="1 edges differ"):
        dual_contour(np.zeros(lattice.shape + (3,)), edge, lattice)


def test_single_patch_cells_keep_cell_plus_offset():
    """A smooth blob has only one-patch cells: same vertices as one vertex per cell."""
    x, y, z = np.mgrid[:12, :12, :12]
    lattice = pad_to_lattice((x - 5.5) ** 2 + (y - 5.5) ** 2 + (z - 5.5) ** 2 < 20)
    vertex = np.random.default_rng(3).random(lattice.shape + (3,)) * 1.4 - 0.2
    edge = crossed_edges(lattice)
    manifold = dual_contour(vertex, edge, lattice)
    per_cell = dual_contour(vertex, edge, None)
    np.testing.assert_array_equal(manifold[0], per_cell[0])
    assert len(manifold[1]) == len(per_cell[1])


@pytest.mark.parametrize("second", [(1, 1, 0), (1, 1, 1)])
def test_voxels_touching_at_an_edge_or_corner_stay_apart(second):
    """Two voxels sharing only an edge (or a corner) give two closed octahedra, 16 vertices."""
    occupancy = np.zeros((2, 2, 2), bool)
    occupancy[0, 0, 0] = occupancy[second] = True
    lattice = pad_to_lattice(occupancy)
    offsets = surface_nets_lattice(lattice)
    vertices, faces = dual_contour(offsets, crossed_edges(lattice), lattice)
    assert len(vertices) == 16 and len(faces) == 24
    assert np.all(edge_use_counts(faces) == 2)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    assert mesh.body_count == 2 and mesh.is_winding_consistent and mesh.volume > 0
    # surface-nets offsets: each patch vertex is that patch's own surface-nets point, so every
    # vertex sits where a lone voxel's would: 1/6 from its voxel centre along each axis
    centres = np.argwhere(lattice)
    l1 = np.abs(vertices[:, None] - centres[None]).sum(axis=2).min(axis=1)
    np.testing.assert_allclose(l1, 0.5, atol=1e-6)


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
    # cells 2k and 2k + 1 put their vertices on the same x: x offset 1 for even cells, 0 for odd
    vertex[::2, :, :, 0], vertex[1::2, :, :, 0] = 1.0, 0.0
    plain = dual_contour(vertex, crossed_edges(lattice), lattice)
    merged = dual_contour(vertex, crossed_edges(lattice), lattice, merge_vertices=True)
    distinct = np.unique(plain[0], axis=0)
    assert len(distinct) < len(plain[0])
    assert np.array_equal(np.unique(merged[0], axis=0), distinct)
    assert len(merged[1]) < len(plain[1])
    assert np.all(np.sort(merged[1], axis=1)[:, :-1] != np.sort(merged[1], axis=1)[:, 1:])


def test_drop_small_components_reindexes():
    vertices = np.arange(18, dtype=float).reshape(6, 3)
    faces = np.array([[0, 1, 2], [3, 4, 5], [3, 5, 4]])
    kept_vertices, kept_faces = drop_small_components(vertices, faces, 2)
    assert np.array_equal(kept_vertices, vertices[3:]) and kept_faces.max() == 2
