import numpy as np
import pytest

from agndc_core import GridError, VoxelGrid
from agndc_core.grid import LATTICE_PAD, pad_to_lattice, pool_occupancy, scale_lattice


def test_index_world_round_trip():
    grid = VoxelGrid.from_spacing(np.ones((3, 4, 5), bool), (0.5, 0.25, 2.0), (1.0, -2.0, 3.0))
    points = np.array([[0, 0, 0], [2, 3, 4]], float)
    world = grid.index_to_world(points)
    assert np.allclose(world, [[1, -2, 3], [2, -1.25, 11]])
    assert np.allclose(grid.world_to_index(world), points)
    assert np.allclose(grid.voxel_size, (0.5, 0.25, 2.0))


@pytest.mark.parametrize("shape", [(1, 1, 1), (5, 7, 3), (8, 8, 8)])
def test_lattice_padding_is_closed_and_divisible(shape):
    lattice = pad_to_lattice(np.ones(shape, bool))
    assert all(d % 4 == 0 for d in lattice.shape)
    assert lattice.sum() == np.prod(shape)
    assert lattice[LATTICE_PAD:LATTICE_PAD + shape[0], LATTICE_PAD:LATTICE_PAD + shape[1],
                   LATTICE_PAD:LATTICE_PAD + shape[2]].all()
    for axis in range(3):  # first and last layers are empty: the surface is closed
        assert not lattice.take(0, axis=axis).any() and not lattice.take(-1, axis=axis).any()


def test_pooling_and_scale_positions():
    lattice = np.zeros((8, 8, 8), bool)
    lattice[3, 4, 5] = True
    coarse = pool_occupancy(lattice)
    assert coarse.shape == (4, 4, 4) and coarse.sum() == 1 and coarse[1, 2, 2]
    offset, spacing = scale_lattice(1)
    # coarse point 1 covers fine points 2 and 3: its centre is 2.5
    assert spacing * 1 + offset == 2.5


@pytest.mark.parametrize("bad, message", [
    (np.zeros((4, 4)), "3-D"),
    (np.zeros((0, 4, 4)), "zero-length"),
    (np.full((2, 2, 2), 0.5), "binary"),
    (np.array([[["a"]]]), "dtype"),
])
def test_bad_arrays_are_named(bad, message):
    with pytest.raises(GridError, match=message):
        VoxelGrid(bad)


def test_numeric_binary_and_empty_grid():
    grid = VoxelGrid(np.eye(3)[None].repeat(2, 0).astype(np.float32))
    assert grid.occupancy.dtype == bool and grid.occupancy.sum() == 6
    with pytest.raises(GridError, match="empty"):
        VoxelGrid(np.zeros((3, 3, 3), bool)).check_not_trivial()


def test_singular_affine_refused():
    with pytest.raises(GridError, match="singular"):
        VoxelGrid(np.ones((2, 2, 2), bool), np.zeros((4, 4)))


def test_lattice_to_world_is_index_to_world_after_the_pad():
    from agndc_core.grid import LATTICE_PAD, VoxelGrid, lattice_to_world

    affine = np.array([[0, -2.0, 0, 5], [0.5, 0, 0, -1], [0, 0, 3, 2], [0, 0, 0, 1]])
    grid = VoxelGrid(np.ones((2, 3, 4), bool), affine)
    points = np.random.default_rng(0).random((7, 3)) * 5
    np.testing.assert_allclose(lattice_to_world(points + LATTICE_PAD, affine),
                               grid.index_to_world(points))
    # by hand: voxel (1, 2, 3) sits at affine @ (1, 2, 3, 1)
    np.testing.assert_allclose(lattice_to_world([[2, 3, 4]], affine), [[1.0, -0.5, 11.0]])


def test_occupancy_pyramid_ors_each_block():
    from agndc_core.grid import occupancy_pyramid

    lattice = np.zeros((8, 8, 4), bool)
    lattice[5, 2, 3] = True
    g = occupancy_pyramid(lattice, 2)
    assert [x.shape for x in g] == [(8, 8, 4), (4, 4, 2), (2, 2, 1)]
    assert g[1].sum() == 1 and g[1][2, 1, 1] and g[2].sum() == 1 and g[2][1, 0, 0]
