"""Surface nets (fast against naive) and the two no-weights methods it brings: surfacenets and
mc_taubin through ``pipeline.remesh``."""

import numpy as np
import pytest
import trimesh

from agndc_core.grid import VoxelGrid, crossed_edges, surface_cells
from agndc_core.pipeline import remesh
from agndc_core.surfacenets import (
    CENTRE,
    surface_nets_cells,
    surface_nets_lattice,
    surface_nets_offsets_naive,
)
from conftest import edge_use_counts


def random_lattices(count=60, seed=14):
    """Seeded random (X, Y, Z) bool lattices, each side in 3..9, density in 0.1..0.9."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        shape = tuple(rng.integers(3, 10, size=3))
        density = rng.uniform(0.1, 0.9)
        yield rng.random(shape) < density


def test_fast_equals_naive_on_random_grids():
    lattices = list(random_lattices())
    assert len(lattices) >= 50
    for lattice in lattices:
        fast = surface_nets_lattice(lattice)
        naive = surface_nets_offsets_naive(lattice)
        assert fast.shape == naive.shape == lattice.shape + (3,)
        assert fast.dtype == naive.dtype == np.float32
        np.testing.assert_array_equal(fast, naive)


def test_surface_nets_of_some_cells_equal_the_dense_field():
    rng = np.random.default_rng(3)
    for lattice in random_lattices(20, seed=5):
        cell_shape = tuple(n - 1 for n in lattice.shape)
        cells = np.argwhere(rng.random(cell_shape) < 0.5)  # any subset, any order
        rng.shuffle(cells)
        flat = np.ravel_multi_index(cells.T, lattice.shape)
        np.testing.assert_array_equal(surface_nets_cells(lattice, flat),
                                      surface_nets_lattice(lattice)[tuple(cells.T)])


def test_surface_cells_are_the_cells_off_centre():
    for lattice in random_lattices(20, seed=6):
        dense = surface_nets_lattice(lattice)
        cells = np.argwhere(surface_cells(crossed_edges(lattice)))
        off_centre = np.argwhere(np.any(dense != CENTRE, axis=-1))
        # a cell with crossed edges can average back to the centre (opposite crossings), so
        # every off-centre cell is a surface cell, and every surface cell has a crossed edge
        assert set(map(tuple, off_centre)) <= set(map(tuple, cells))
        assert all(len({bool(lattice[tuple(c + d)]) for d in np.ndindex(2, 2, 2)}) == 2
                   for c in cells)


def box_grid(block=(10, 12, 14), pad=3):
    """A solid block of voxels inside empty layers: (grid, lo (3,), hi (3,)) voxel indices of
    the block's first and last voxel per axis."""
    block = np.array(block)
    occupancy = np.zeros(tuple(block + 2 * pad), dtype=bool)
    occupancy[pad:pad + block[0], pad:pad + block[1], pad:pad + block[2]] = True
    return VoxelGrid(occupancy), np.full(3, pad), pad + block - 1


def test_box_vertices_sit_on_the_midway_planes():
    """Flat-face cells have 4 crossed edges, all along the face normal: their mean lies on the
    plane half a voxel outside the last inside centre, and at the cell centre in-plane. Cells on
    the box's 12 edges average 2 + 2 midpoints, so they sit a quarter voxel inside both planes;
    the 8 corner cells average 3 midpoints, 1/3 voxel inside all three planes."""
    grid, lo, hi = box_grid()
    result = remesh(grid, method="surfacenets")
    vertices = result.vertices
    used = np.unique(result.faces)
    assert len(used) == len(vertices)  # every vertex is a face vertex
    below, above = vertices < lo, vertices > hi  # (V, 3) outside the inside centres, per axis
    outside = below | above
    n_out = outside.sum(axis=1)
    # distance from the midway plane, inward, on each axis where the vertex is outside
    depth = np.where(below, vertices - (lo - 0.5), (hi + 0.5) - vertices)
    expected = {1: 0.0, 2: 0.25, 3: 1.0 / 3.0}
    for n, inward in expected.items():
        mine = n_out == n
        assert np.abs(depth[mine][outside[mine]] - inward).max() < 1e-6
    # in-plane, flat-face vertices sit at cell centres (integer + 1/2)
    flat = n_out == 1
    in_plane = vertices[flat][~outside[flat]]
    assert np.abs(in_plane - np.floor(in_plane) - 0.5).max() < 1e-6
    # one vertex per surface cell: faces, then edges, then corners
    nx, ny, nz = hi - lo  # cells between the inside centres along each axis
    assert (n_out == 1).sum() == 2 * (ny * nz + nx * nz + nx * ny)
    assert (n_out == 2).sum() == 4 * (nx + ny + nz)
    assert (n_out == 3).sum() == 8
    assert n_out.min() == 1


def sphere_grid(n=24, radius=8.3):
    centre = (n - 1) / 2.0
    points = np.indices((n, n, n)).transpose(1, 2, 3, 0) - centre
    return VoxelGrid.from_spacing(np.linalg.norm(points, axis=-1) < radius, voxel_size=0.1,
                                  origin=(1.0, -2.0, 0.5)), radius * 0.1


@pytest.mark.parametrize("method", ["surfacenets", "mc_taubin"])
def test_sphere_is_closed_and_outward(method):
    grid, radius = sphere_grid()
    result = remesh(grid, method=method)
    assert len(result.faces) > 0
    assert np.all(edge_use_counts(result.faces) == 2)  # closed, edge-manifold
    volume = trimesh.Trimesh(result.vertices, result.faces, process=False).volume
    assert volume > 0
    assert abs(volume / (4.0 / 3.0 * np.pi * radius**3) - 1.0) < 0.06


def test_taubin_moves_vertices_but_keeps_marching_cubes_topology():
    grid, _ = sphere_grid()
    mc = remesh(grid, method="mc")
    smooth = remesh(grid, method="mc_taubin")
    np.testing.assert_array_equal(smooth.faces, mc.faces)
    moved = np.linalg.norm(smooth.vertices - mc.vertices, axis=1)
    assert moved.max() > 1e-3 * 0.1  # smoothing happened (voxel size 0.1)
    assert moved.max() < 0.5 * 0.1  # ... without moving any vertex half a voxel
    assert "taubin smoothing" in smooth.timings


def test_the_torch_prior_equals_the_numpy_surface_nets():
    """The networks' prior in training (torch, batched) is the same sums as the product's."""
    import torch

    from agndc_core.nn.common import surface_nets_offsets

    rng = np.random.default_rng(3)
    batch = rng.random((3, 9, 11, 7)) < 0.4
    torch_out = surface_nets_offsets(torch.from_numpy(batch)).numpy()
    for lattice, theirs in zip(batch, torch_out):
        np.testing.assert_array_equal(surface_nets_lattice(lattice), theirs)
