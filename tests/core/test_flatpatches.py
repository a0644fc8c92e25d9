"""Flat patches (fast against naive) and the invariants they promise: flat voxel faces come out
exactly flat, at the network's mean depth on the shape's outermost layers and mid-layer inside
its extent, terraces and everything else are left alone; then the same
through ``pipeline.remesh`` with the shipped network. Then the source bounds: the faces that
bound a voxelised mesh land on its bounding box, and nothing lies beyond it. Then the terraced
planes and the stepped floors."""

import numpy as np
import pytest

from agndc_core import flatpatches
from agndc_core.flatpatches import (
    flatten_patches,
    flatten_patches_naive,
    pure_splits,
    snap_to_bounds,
    snap_to_bounds_naive,
)
from agndc_core.grid import VoxelGrid
from agndc_core.pipeline import remesh
from agndc_core.surfacenets import surface_nets_lattice
from agndc_core.tolerances import tol


def block_lattice(shape=(14, 15, 16), lo=(3, 4, 5), hi=(10, 12, 13)):
    """A lattice holding one solid block of points lo..hi-1."""
    lattice = np.zeros(shape, dtype=bool)
    lattice[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True
    return lattice


def ball_lattice(n=16, radius=5.3):
    x, y, z = np.mgrid[:n, :n, :n] - (n - 1) / 2 + 0.21
    return x**2 + y**2 + z**2 < radius**2


def noisy_vertex(lattice, seed=3):
    rng = np.random.default_rng(seed)
    return rng.uniform(0.0, 1.0, lattice.shape + (3,)).astype(np.float32)


def random_lattices(count=24, seed=5):
    """Unions of random blocks, half of them with a ball: flat patches, terraces, both kinds."""
    rng = np.random.default_rng(seed)
    for index in range(count):
        n = int(rng.integers(8, 12))
        lattice = np.zeros((n, n, n), dtype=bool)
        for _ in range(3):
            lo = rng.integers(1, n // 2, 3)
            hi = lo + rng.integers(1, n // 2, 3)
            lattice[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = True
        if index % 2:
            lattice |= ball_lattice(n, rng.uniform(2.0, 4.0))
        yield lattice


@pytest.mark.parametrize("slab", [32, 3, 1])
def test_fast_equals_naive(slab, monkeypatch):
    # slabs of 3 and 1 layers put patches and their terrace neighbours in different slabs
    monkeypatch.setattr(flatpatches, "SLAB_LAYERS", slab)
    changed = 0
    for seed, lattice in enumerate(random_lattices()):
        vertex = noisy_vertex(lattice, seed)
        fast = flatten_patches(lattice, vertex)
        naive = flatten_patches_naive(lattice, vertex)
        assert fast.shape == vertex.shape and fast.dtype == vertex.dtype
        np.testing.assert_allclose(fast, naive, atol=1e-6)
        changed += int((fast != vertex).sum())
    assert changed > 100  # the comparison saw patches being flattened


def test_box_faces_become_flat_at_their_mean_depth():
    lattice = block_lattice()
    vertex = noisy_vertex(lattice)
    out = flatten_patches(lattice, vertex)
    lo, hi = (3, 4, 5), (10, 12, 13)
    for axis in range(3):
        others = [a for a in range(3) if a != axis]
        # the cells inside the face (not on the block's edges) of the low and high faces
        for layer in (lo[axis] - 1, hi[axis] - 1):
            index = [slice(lo[a], hi[a] - 1) for a in range(3)]
            index[axis] = layer
            face_in, face_out = vertex[tuple(index)][..., axis], out[tuple(index)][..., axis]
            assert face_in.size == np.prod([hi[a] - 1 - lo[a] for a in others])
            assert np.ptp(face_out) == 0.0  # exactly flat
            assert face_out.flat[0] == pytest.approx(face_in.mean(), abs=1e-6)
    # only coordinates along a face's axis changed, and only on the six faces
    changed = out != vertex
    same = vertex.copy()
    assert flatten_patches(lattice, same, in_place=True) is same
    np.testing.assert_array_equal(same, out)
    assert changed.sum() == sum(2 * np.prod([hi[a] - 1 - lo[a] for a in range(3) if a != axis])
                                for axis in range(3))


def test_the_longest_sides_bounding_faces_go_mid_layer():
    # x spans 11 layers of points, y 8, z 6: voxelize puts a mesh's bounding faces mid-layer
    # along its longest side, so the +-x faces take MIDPOINT; y and z keep the network's mean
    lattice = block_lattice(shape=(18, 14, 12), lo=(3, 4, 5), hi=(14, 12, 11))
    assert flatpatches.longest_axis(lattice) == 0
    vertex = noisy_vertex(lattice)
    out = flatten_patches(lattice, vertex)
    # each face's whole patch: the cells whose 4 corners along the other axes are in the block
    assert np.all(out[2, 4:11, 5:10, 0] == flatpatches.MIDPOINT)
    assert np.all(out[13, 4:11, 5:10, 0] == flatpatches.MIDPOINT)
    for index in ((slice(3, 13), 3, slice(5, 10), 1), (slice(3, 13), slice(4, 11), 10, 2)):
        assert np.ptp(out[index]) == 0.0
        assert out[index].flat[0] == pytest.approx(vertex[index].mean(), abs=1e-6)
    np.testing.assert_allclose(out, flatten_patches_naive(lattice, vertex), atol=1e-6)
    # a tie for the longest side: every bounding face keeps the network's mean
    tie = block_lattice(shape=(18, 18, 12), lo=(3, 3, 5), hi=(14, 14, 11))
    assert flatpatches.longest_axis(tie) is None
    vertex = noisy_vertex(tie)
    out = flatten_patches(tie, vertex)
    assert out[2, 3, 5, 0] == pytest.approx(vertex[2, 3:13, 5:10, 0].mean(), abs=1e-6)
    assert flatpatches.longest_axis(np.zeros((4, 4, 4), dtype=bool)) is None


def test_terraces_are_left_alone():
    # a plane slanted by one layer every 4 cells: every flat patch has a neighbour one layer
    # up or down within reach
    n = 20
    x, _, z = np.mgrid[:n, :n, :n]
    lattice = (z < 4 + x / 4.0) & (x > 0) & (x < n - 1)
    lattice[:, [0, n - 1], :] = False
    lattice[..., 0] = False
    vertex = noisy_vertex(lattice)
    top = pure_splits(lattice, 2, lower_inside=True)
    assert top.sum() > 100  # the terraces are there
    out = flatten_patches(lattice, vertex)
    # the slanted top keeps the raw values; the flat bottom (lower corners outside) is flattened
    cells = out[:-1, :-1, :-1, 2], vertex[:-1, :-1, :-1, 2]
    np.testing.assert_array_equal(cells[0][top], cells[1][top])
    bottom = pure_splits(lattice, 2, lower_inside=False)
    assert bottom.sum() > 100 and np.ptp(cells[0][bottom]) == 0.0


def test_a_step_of_two_layers_is_no_terrace():
    # a plateau and a strip raised 2 layers above it: a wall, not a terrace; both are flattened
    n = 24
    lattice = np.zeros((n, n, n), dtype=bool)
    lattice[2:22, 2:22, 2:10] = True
    lattice[2:8, 2:22, 10:12] = True
    vertex = noisy_vertex(lattice)
    out = flatten_patches(lattice, vertex)
    plateau, strip = out[8:21, 2:21, 9, 2], out[2:7, 2:21, 11, 2]
    assert np.ptp(plateau) == 0.0 and np.ptp(strip) == 0.0
    # the strip bounds the shape (its outermost layer along z): the network's mean depth; the
    # plateau lies inside the shape's extent: the middle of its layer
    assert strip[0, 0] == pytest.approx(vertex[2:7, 2:21, 11, 2].mean(), abs=1e-6)
    assert plateau[0, 0] == flatpatches.MIDPOINT
    assert vertex[8:21, 2:21, 9, 2].mean() != pytest.approx(flatpatches.MIDPOINT, abs=1e-3)
    # one layer instead of two is a terrace within reach: the plateau keeps its raw values
    lattice[2:8, 2:22, 11] = False
    out = flatten_patches(lattice, vertex)
    assert tol.terrace_reach >= 1  # the strip's edge is 1 cell from the plateau
    np.testing.assert_array_equal(out[8:21, 2:21, 9, 2], vertex[8:21, 2:21, 9, 2])


def test_half_ball_cut_is_flattened_its_pole_is_not():
    lattice = ball_lattice(10, 4.0)
    lattice[..., :5] = False  # half a ball: flat at its cut, terraced around its pole
    vertex = noisy_vertex(lattice)
    out = flatten_patches(lattice, vertex)
    cut = pure_splits(lattice, 2, lower_inside=False)  # (split axis last: z already is)
    assert cut.sum() > 10 and np.ptp(out[:-1, :-1, :-1, 2][cut]) == 0.0
    pole = pure_splits(lattice, 2, lower_inside=True)
    assert pole.any()
    np.testing.assert_array_equal(out[:-1, :-1, :-1, 2][pole], vertex[:-1, :-1, :-1, 2][pole])


def test_remesh_gives_the_shipped_network_flat_box_faces():
    occupancy = np.zeros((20, 22, 24), dtype=bool)
    occupancy[3:17, 4:18, 5:19] = True
    grid = VoxelGrid(occupancy)
    raw = remesh(grid, method="agndc", threads=1, flat_patches=False)
    flat = remesh(grid, method="agndc", threads=1)
    assert "flat patches" in flat.timings and "flat patches" not in raw.timings

    def spread_on_faces(vertices):
        # vertices near a face plane, at least 2 voxels from the block's other faces
        spreads = []
        for axis, (lo, hi) in enumerate([(3, 16), (4, 17), (5, 18)]):
            inner = np.ones(len(vertices), dtype=bool)
            for other, (olo, ohi) in enumerate([(3, 16), (4, 17), (5, 18)]):
                if other != axis:
                    inner &= (vertices[:, other] > olo + 2) & (vertices[:, other] < ohi - 2)
            for plane in (lo - 0.5, hi + 0.5):
                on = inner & (np.abs(vertices[:, axis] - plane) < 0.5)
                assert on.sum() > 50
                spreads.append(np.ptp(vertices[on, axis]))
        return max(spreads)

    assert spread_on_faces(flat.vertices) < 1e-5
    assert spread_on_faces(raw.vertices) > 1e-3  # the network alone is not flat


def test_cli_remesh_flattens_unless_told_not_to(tmp_path):
    import trimesh

    from agndc_core.cli import main
    from agndc_core.gridio import load_mesh

    source = tmp_path / "box.obj"
    trimesh.creation.box((1.0, 0.8, 0.6)).export(source)
    spreads = {}
    for flag in ([], ["--no-flat-patches"]):
        output = tmp_path / f"out{len(flag)}.ply"
        # the grid alone: with the source bounds the top face lies on the box either way
        assert main(["remesh", str(source), "-o", str(output), "--res", "24",
                     "--no-source-bounds", *flag]) == 0
        vertices, _ = load_mesh(output)
        # the top face (z = 0.3; a voxel is 1/22): vertices near it, well inside it in x and y
        top = (np.abs(vertices[:, 2] - 0.3) < 0.03) & (np.abs(vertices[:, 0]) < 0.35) \
            & (np.abs(vertices[:, 1]) < 0.25)
        assert top.sum() > 20
        spreads[bool(flag)] = np.ptp(vertices[top, 2])
    assert spreads[False] < 1e-6  # flat
    assert spreads[True] > 1e-4  # the network's raw depths


# ---------------------------------------------------------------------------- source bounds
def extreme_layers(lattice):
    """(first, last) occupied layer of points along each axis: (3, 2) int."""
    return np.array([[np.flatnonzero(lattice.any(axis=tuple(b for b in range(3) if b != a)))[i]
                      for i in (0, -1)] for a in range(3)])


def bounds_in_layers(lattice, rng):
    """Random (2, 3) bounds, each plane inside its side's outermost layer of cells."""
    ends = extreme_layers(lattice)
    return np.stack([ends[:, 0] - 1 + rng.uniform(0, 1, 3), ends[:, 1] + rng.uniform(0, 1, 3)])


def test_snap_to_bounds_fast_equals_naive():
    rng = np.random.default_rng(11)
    changed = 0
    for seed, lattice in enumerate(random_lattices(16)):
        vertex = noisy_vertex(lattice, seed)
        bounds = bounds_in_layers(lattice, rng)
        if seed % 4 == 3:  # some sides' planes beyond their layer: those sides are left alone
            bounds[0, seed % 3] -= 1.5
            bounds[1, (seed + 1) % 3] += 1.5
        fast = snap_to_bounds(lattice, vertex, bounds)
        naive = snap_to_bounds_naive(lattice, vertex, bounds)
        assert fast.shape == vertex.shape and fast.dtype == vertex.dtype
        np.testing.assert_allclose(fast, naive, atol=1e-6)
        changed += int((fast != vertex).sum())
    assert changed > 100


def test_a_block_lands_on_its_bounds_and_nothing_else_moves():
    lo, hi = (3, 4, 5), (10, 12, 13)
    lattice = block_lattice(lo=lo, hi=hi)
    vertex = noisy_vertex(lattice)
    planes = np.array([[2.3, 3.6, 4.55], [9.7, 11.2, 12.01]])  # in the outermost layers
    out = snap_to_bounds(lattice, vertex, planes)
    same = vertex.copy()
    assert snap_to_bounds(lattice, same, planes, in_place=True) is same
    np.testing.assert_array_equal(same, out)
    for axis in range(3):
        for side, layer in ((0, lo[axis] - 1), (1, hi[axis] - 1)):
            index = [slice(lo[a], hi[a] - 1) for a in range(3)]  # the face's inner cells
            index[axis] = layer
            face = out[tuple(index)][..., axis]
            assert np.all(face == np.float32(planes[side, axis] - layer))
            # no vertex of the outermost layer beyond the plane (the face's edges and corners)
            whole = np.take(out[..., axis], layer, axis=axis) + layer
            assert np.all(whole <= planes[1, axis] + 1e-6) if side else \
                np.all(whole >= planes[0, axis] - 1e-6)
    # only coordinates along an axis, only in that axis' two outermost layers, changed
    moved = np.argwhere(out != vertex)
    assert len(moved) > 0
    for *cell, axis in moved:
        assert cell[axis] in (lo[axis] - 1, hi[axis] - 1)


def test_a_plane_outside_its_layer_changes_nothing():
    lattice = block_lattice()
    vertex = noisy_vertex(lattice)
    # the mesh reaches 1.4 cells beyond the grid's outermost layer (a part too thin for voxels)
    planes = np.array([[2.0 - 1.4, 3.5, 4.5], [9.5, 11.5, 12.5]])
    out = snap_to_bounds(lattice, vertex, planes)
    np.testing.assert_array_equal(out[2, :, :, 0], vertex[2, :, :, 0])  # the low x side
    assert (out[9, :, :, 0] != vertex[9, :, :, 0]).any()  # the other sides still land


def test_a_balls_pole_is_only_kept_inside_its_plane():
    lattice = ball_lattice(10, 4.0)  # its pole is a terrace (test_half_ball_cut_...)
    vertex = noisy_vertex(lattice)
    ends = extreme_layers(lattice)
    planes = np.stack([ends[:, 0] - 0.5, ends[:, 1] + 0.5])
    out = snap_to_bounds(lattice, vertex, planes)
    top = ends[2, 1]
    pole = pure_splits(lattice, 2, lower_inside=True)[..., top]
    assert pole.any()
    raw, got = vertex[:-1, :-1, top, 2][pole], out[:-1, :-1, top, 2][pole]
    # a terrace: not put on the plane, only clamped to it
    np.testing.assert_array_equal(got, np.minimum(raw, 0.5))
    assert (raw < 0.5).any()


def test_remesh_keeps_a_meshs_bounding_box():
    """Mesh input: the dual methods' output has the mesh's own bounding box, and its axis-aligned
    bounding faces lie on it; without the source bounds (or with marching cubes) it does not."""
    import trimesh

    from agndc_core.pipeline import remesh_mesh

    box = trimesh.creation.box((1.0, 0.613, 0.377))
    for method in ("surfacenets", "agndc", "undc"):
        result = remesh_mesh(box.vertices, box.faces, resolution=32, method=method, threads=1)
        voxel = result.grid.voxel_size[0]
        assert "source bounds" in result.timings
        np.testing.assert_allclose(result.vertices.min(0), box.bounds[0], atol=1e-5 * voxel)
        np.testing.assert_allclose(result.vertices.max(0), box.bounds[1], atol=1e-5 * voxel)
        # every vertex near a face plane is on it (flat, at the true depth)
        distance = np.abs(np.abs(result.vertices) - box.extents / 2) / voxel
        assert np.all((distance.min(axis=1) < 1e-4) | (distance.min(axis=1) > 0.75))
        alone = remesh_mesh(box.vertices, box.faces, resolution=32, method=method, threads=1,
                            source_bounds=False)
        assert "source bounds" not in alone.timings
        assert np.abs(alone.vertices.max(0) - box.bounds[1]).max() > 0.05 * voxel
    mc = [remesh_mesh(box.vertices, box.faces, resolution=32, method="mc", source_bounds=flag)
          for flag in (True, False)]
    np.testing.assert_array_equal(mc[0].vertices, mc[1].vertices)


def test_a_mirrored_grid_keeps_its_bounds():
    """A grid whose x axis runs backwards in world space (negative voxel size): the bounds'
    min and max corners swap in index space."""
    import trimesh

    from agndc_core.pipeline import remesh
    from agndc_core.voxelize import voxelize

    box = trimesh.creation.box((1.0, 0.613, 0.377))
    grid = voxelize(box.vertices, box.faces, 24)
    affine = grid.affine.copy()
    affine[0, 0] = -affine[0, 0]
    affine[0, 3] = grid.affine[0, 3] + (grid.shape[0] - 1) * grid.affine[0, 0]
    mirrored = VoxelGrid(grid.occupancy[::-1], affine, "mirrored", grid.source_bounds)
    result = remesh(mirrored, method="surfacenets")
    np.testing.assert_allclose(result.vertices.min(0), box.bounds[0], atol=1e-6)
    np.testing.assert_allclose(result.vertices.max(0), box.bounds[1], atol=1e-6)


def test_voxelize_records_the_bounds_and_the_grid_checks_them():
    import trimesh

    from agndc_core.errors import GridError
    from agndc_core.voxelize import voxelize

    box = trimesh.creation.box((1.0, 0.6, 0.4))
    # a vertex that no face uses is not part of the surface
    vertices = np.vstack([box.vertices, [[5.0, 5.0, 5.0]]])
    grid = voxelize(vertices, box.faces, 16)
    np.testing.assert_array_equal(grid.source_bounds, box.bounds)
    with pytest.raises(GridError, match="source_bounds"):
        VoxelGrid(grid.occupancy, grid.affine, "g", np.array([[1.0, 0, 0], [0, 1.0, 1.0]]))
    with pytest.raises(GridError, match="source_bounds"):
        VoxelGrid(grid.occupancy, grid.affine, "g", np.zeros(3))


def test_cli_keeps_the_bounds_unless_told_not_to(tmp_path):
    import trimesh

    from agndc_core.cli import main
    from agndc_core.gridio import load_mesh

    source = tmp_path / "box.obj"
    box = trimesh.creation.box((1.0, 0.613, 0.377))
    box.export(source)
    tops = {}
    for flag in ([], ["--no-source-bounds"]):
        output = tmp_path / f"out{len(flag)}.ply"
        assert main(["remesh", str(source), "-o", str(output), "--res", "24",
                     "--method", "surfacenets", *flag]) == 0
        vertices, _ = load_mesh(output)
        tops[bool(flag)] = vertices[:, 2].max()
    assert tops[False] == pytest.approx(0.377 / 2, abs=1e-6)
    assert abs(tops[True] - 0.377 / 2) > 1e-3


# ------------------------------------------------------------------ terraced planes


def tilted_lattice(shape=(40, 36, 12), slope=(0.05, 0.03), height=5.3):
    """Points below a plane tilted a few degrees off z: terraces one layer apart."""
    x, y, z = np.indices(shape, dtype=np.float64)
    return z < height + slope[0] * x + slope[1] * y


def surface_nets_noise(lattice, seed=0, noise=0.15):
    """Surface nets vertices with a network-like noise, clipped into the cells."""
    from agndc_core.surfacenets import surface_nets_lattice

    rng = np.random.default_rng(seed)
    vertex = surface_nets_lattice(lattice) + rng.normal(0, noise, lattice.shape + (3,))
    return np.clip(vertex, 0.0, 1.0).astype(np.float32)


def terraced_cases():
    yield tilted_lattice()
    yield np.transpose(tilted_lattice((36, 30, 10), (-0.04, 0.02), 4.7), (2, 0, 1))
    yield ~tilted_lattice((30, 30, 10), (0.08, -0.06), 6.2)
    yield ball_lattice(16, 5.3)
    yield from random_lattices(8, seed=11)


def test_terraced_planes_fast_equals_naive():
    moved = 0
    for seed, lattice in enumerate(terraced_cases()):
        vertex = surface_nets_noise(lattice, seed)
        fast = flatpatches.fit_terraced_planes(lattice, vertex)
        naive = flatpatches.fit_terraced_planes_naive(lattice, vertex)
        np.testing.assert_allclose(fast, naive, atol=1e-5)
        moved += int(np.count_nonzero(np.abs(fast - vertex) > 1e-6))
    assert moved > 500  # the tilted planes were fitted


def test_a_tilted_plane_comes_out_on_one_plane_and_pinned():
    lattice = tilted_lattice()
    vertex = surface_nets_noise(lattice, 4)
    pinned = np.zeros(vertex.shape, dtype=bool)
    out = flatpatches.fit_terraced_planes(lattice, vertex, pinned=pinned)
    cells = np.argwhere(pinned[..., 2])
    # every terrace cell
    assert len(cells) == np.count_nonzero(pure_splits(lattice, 2, True))
    u, v = cells[:, 0] + out[tuple(cells.T)][:, 0], cells[:, 1] + out[tuple(cells.T)][:, 1]
    h = cells[:, 2] + out[tuple(cells.T)][:, 2]
    coef, *_ = np.linalg.lstsq(np.c_[u, v, np.ones_like(u)], h, rcond=None)
    # one plane (float32 offsets), but where it leaves a cell's layer by up to the slack
    deviation = np.abs(h - np.c_[u, v, np.ones_like(u)] @ coef)
    assert np.percentile(deviation, 99) < 1e-3 and deviation.max() <= tol.terrace_slack
    # ... the true one (z = 5.3 + 0.05 x + 0.03 y, lattice points at integers), within noise
    assert np.abs(coef[:2] - [0.05, 0.03]).max() < 0.003 and abs(coef[2] - 5.3) < 0.1
    assert not pinned[..., :2].any()  # only the coordinate along the split axis is written


def test_a_plane_tilted_one_degree_is_fitted_inside_its_layers(monkeypatch):
    """Two or three terraces tens of cells wide whose vertices follow the steps (each at its
    layer's middle, as a network that cannot see the plane leaves them): their least-squares
    plane leaves the terraces' far ends by more than the slack, and only the projections into
    the layers find the plane that crosses every cell."""
    lattice = tilted_lattice((120, 40, 8), (0.017, 0.004), 3.9)  # ~1° off z, narrow end terraces
    rng = np.random.default_rng(5)
    vertex = np.clip(surface_nets_lattice(lattice) + rng.normal(0, 0.03, lattice.shape + (3,)),
                     0.0, 1.0).astype(np.float32)
    vertex[..., 2] = 0.5 + rng.normal(0, 0.03, lattice.shape)  # the staircase
    terraces = pure_splits(lattice, 2, True)
    assert len(np.unique(np.nonzero(terraces)[2])) >= 2

    def fitted_cells(projections):
        monkeypatch.setattr(tol, "terrace_projections", projections)
        pinned = np.zeros(vertex.shape, dtype=bool)
        out = flatpatches.fit_terraced_planes(lattice, vertex, pinned=pinned)
        return out, np.argwhere(pinned[..., 2])

    passes = tol.terrace_projections
    assert len(fitted_cells(0)[1]) == 0  # the least-squares plane alone is rejected
    out, cells = fitted_cells(passes)
    assert len(cells) == np.count_nonzero(terraces)
    u, v = cells[:, 0] + out[tuple(cells.T)][:, 0], cells[:, 1] + out[tuple(cells.T)][:, 1]
    h = cells[:, 2] + out[tuple(cells.T)][:, 2]
    coef, *_ = np.linalg.lstsq(np.c_[u, v, np.ones_like(u)], h, rcond=None)
    # one plane, clipped into the layers it leaves by at most a third of the slack
    deviation = np.abs(h - np.c_[u, v, np.ones_like(u)] @ coef)
    assert np.percentile(deviation, 90) < 1e-3 and deviation.max() <= tol.terrace_slack / 3
    # ... tilted along the terraces' steps like the true one (the staircase's heights alone
    # say nothing finer than the layers)
    assert abs(coef[0] - 0.017) < 0.006 and abs(coef[1] - 0.004) < 0.006
    naive = flatpatches.fit_terraced_planes_naive(lattice, vertex)
    np.testing.assert_allclose(out, naive, atol=1e-5)


def cylinder_side(radius=7.4, centre=(10.4, 2.8), shape=(22, 40, 14)):
    """Points inside a cylinder along y, its top side facing +z, and the vertices of a network
    that follows the curve there (each z-split cell at the true height over its centre)."""
    x, y, z = np.indices(shape, dtype=np.float64)
    lattice = (x - centre[0]) ** 2 + (z - centre[1]) ** 2 < radius ** 2
    column = np.arange(shape[0])[:, None, None] + 0.5
    top = centre[1] + np.sqrt(np.maximum(radius ** 2 - (column - centre[0]) ** 2, 0.0))
    vertex = np.full(shape + (3,), 0.5, dtype=np.float32)
    vertex[..., 2] = np.clip(top - np.arange(shape[2])[None, None, :], 0.0, 1.0)
    return lattice, vertex


def test_a_round_side_is_not_fitted_as_a_plane(monkeypatch):
    """The top of a cylinder along an axis reaches the grid as terraces (its top one and a strip
    beside it, one layer down), which pass the plane tests; the vertices follow the curve, which
    a quadratic surface explains, so the surface is left round. With the round test off the
    same surface is flattened (the test can fail)."""
    lattice, vertex = cylinder_side()

    def pinned_along_z():
        pinned = np.zeros(vertex.shape, dtype=bool)
        out = flatpatches.fit_terraced_planes(lattice, vertex, pinned=pinned)
        np.testing.assert_allclose(out, flatpatches.fit_terraced_planes_naive(lattice, vertex),
                                   atol=1e-5)
        return int(np.count_nonzero(pinned[..., 2]))

    assert pinned_along_z() == 0
    monkeypatch.setattr(tol, "terrace_round_share", 2.0)  # no surface is round
    assert pinned_along_z() > 100


def test_round_needs_cells_a_bend_and_the_share_explained():
    cells, bend = tol.terrace_round_cells, tol.terrace_round_bend
    spread = bend ** 2 / tol.terrace_round_share  # the most spread the bend explains enough
    assert flatpatches._round(cells, spread, bend)
    assert not flatpatches._round(cells - 1, spread, bend)  # too few cells
    assert not flatpatches._round(cells, 0.9 * spread, 0.9 * bend)  # too little bend
    assert not flatpatches._round(cells, 1.2 * spread, bend)  # a staircase left unexplained


def test_a_tilted_box_face_remeshed_is_flat():
    """Through remesh with the shipped network: a box face tilted 2° off an axis comes out
    flat (its vertices within a few hundredths of a voxel of one plane), where the network
    alone follows the terraces (~0.2 voxel RMS)."""
    import trimesh

    from agndc_core.pipeline import remesh_mesh

    box = trimesh.creation.box((1.0, 0.8, 0.5))
    rotation = trimesh.transformations.rotation_matrix(np.radians(2.0), [1, 0.3, 0])
    box.apply_transform(rotation)
    result = remesh_mesh(box.vertices, box.faces, resolution=48)
    h = result.grid.voxel_size[0]
    local = result.vertices @ rotation[:3, :3]  # the box's own frame
    top = (np.abs(local[:, 2] - 0.25) < 2 * h) & (np.abs(local[:, 0]) < 0.5 - 3 * h) \
        & (np.abs(local[:, 1]) < 0.4 - 3 * h)
    assert top.sum() > 500
    design = np.c_[local[top, :2], np.ones(top.sum())]
    coef, *_ = np.linalg.lstsq(design, local[top, 2], rcond=None)
    waviness = np.std(local[top, 2] - design @ coef) / h
    assert waviness < 0.05


def test_bends_measure_how_far_a_quadratic_fit_leaves_the_plane():
    """A plane's points bend by nothing; a paraboloid's by the RMS of its quadratic part about
    its best plane (least squares per group, computed directly)."""
    rng = np.random.default_rng(2)
    u, v = rng.uniform(0, 30, (2, 400))
    group = np.repeat([0, 1], 200)
    h = 5 + 0.05 * u - 0.02 * v + np.where(group == 1, 0.006 * (u - 15) ** 2, 0.0)
    plane = flatpatches._fit_planes(u, v, h, group, 2)
    fitted = plane[group, 0] * u + plane[group, 1] * v + plane[group, 2]
    bends = flatpatches._bends(u, v, h, fitted, group, 2)
    assert bends[0] < 1e-9
    mine = group == 1
    design = np.c_[u[mine], v[mine], np.ones(mine.sum())]
    best, *_ = np.linalg.lstsq(design, h[mine], rcond=None)
    expected = np.sqrt(np.mean((h[mine] - design @ best) ** 2))  # the surface is exactly quadratic
    assert bends[1] == pytest.approx(expected, rel=1e-6) and expected > 0.3


# ------------------------------------------------------------------ stepped floors


def recessed_box(n=30, depth_layers=1):
    """A box whose top has a square recess ``depth_layers`` deep inside a 5-cell rim."""
    lattice = np.zeros((n, n, n), dtype=bool)
    lattice[5:25, 5:25, 5:15] = True
    lattice[10:20, 10:20, 15 - depth_layers:15] = False
    return lattice


def stepped_cases():
    """Recesses, a plateau on a ledge, a staircase and random blocks (flat patches, terraces,
    floors)."""
    yield recessed_box()
    yield recessed_box(depth_layers=2)
    plateau = np.zeros((24, 24, 20), dtype=bool)
    plateau[3:21, 3:21, 3:8] = True
    plateau[7:17, 6:18, 8] = True  # one layer above its ledge
    yield plateau
    yield staircase()
    yield from random_lattices(6, seed=13)


def staircase():
    """Six terraces one layer apart along x, each 5 cells deep: the grid of a tilted plane."""
    lattice = np.zeros((40, 20, 20), dtype=bool)
    for step in range(6):
        lattice[5 + 5 * step:10 + 5 * step, 5:15, 5:8 + step] = True
    return lattice


def flat_network(lattice, depth=0.8, noise=0.03, seed=0):
    """Coordinates the network might give a patch it calls flat: ``depth`` give or take
    ``noise`` voxels."""
    rng = np.random.default_rng(seed)
    return (depth + rng.normal(0.0, noise, lattice.shape + (3,))).astype(np.float32)


def test_stepped_floors_fast_equals_naive():
    changed = 0
    for seed, lattice in enumerate(stepped_cases()):
        for depth in (0.8, 0.2, 0.6):
            vertex = flat_network(lattice, depth, seed=seed)
            pinned = np.random.default_rng(seed).random(vertex.shape) < 0.002
            for pin in (None, pinned):
                fast = flatpatches.flatten_stepped_floors(
                    lattice, vertex, pinned=None if pin is None else pin.copy())
                naive = flatpatches.flatten_stepped_floors_naive(lattice, vertex, pin)
                assert fast.dtype == vertex.dtype
                np.testing.assert_allclose(fast, naive, atol=1e-6)
                changed += int((fast != vertex).sum())
    assert changed > 500  # the comparison saw floors being flattened


def test_a_recessed_floor_goes_mid_layer_and_the_rim_keeps_its_mean():
    lattice = recessed_box()
    up = pure_splits(lattice, 2, True)
    layers = np.flatnonzero(up.any(axis=(0, 1)))
    floor, rim = layers[-2], layers[-1]
    vertex = flat_network(lattice)
    assert flatten_patches(lattice, vertex)[up[..., floor].nonzero() + (floor, 2)].std() > 0
    pinned = np.zeros(vertex.shape, dtype=bool)
    out = flatpatches.flatten_stepped_floors(lattice, vertex, pinned=pinned)
    z = out[:-1, :-1, :-1, 2]
    assert up[..., floor].sum() >= 64 and np.all(z[up[..., floor].nonzero() + (floor,)] == 0.5)
    assert pinned[:-1, :-1, :-1, 2][up[..., floor].nonzero() + (floor,)].all()
    # the rim steps down on both of its sides too: it is the shape's outermost layer, the mean
    rim_cells = up[..., rim].nonzero() + (rim,)
    np.testing.assert_allclose(z[rim_cells], vertex[:-1, :-1, :-1, 2][rim_cells].mean(),
                               rtol=1e-6)
    # not where the network's depth is near the midpoint, or not flat, or already placed
    near = flat_network(lattice, 0.5 + tol.floor_offset / 2)
    np.testing.assert_array_equal(flatpatches.flatten_stepped_floors(lattice, near), near)
    noisy = flat_network(lattice, noise=0.2)
    np.testing.assert_array_equal(flatpatches.flatten_stepped_floors(lattice, noisy), noisy)
    taken = np.ones(vertex.shape, dtype=bool)
    np.testing.assert_array_equal(
        flatpatches.flatten_stepped_floors(lattice, vertex, pinned=taken), vertex)


def test_a_staircases_straight_steps_are_left_to_the_network():
    lattice = staircase()
    vertex = flat_network(lattice)
    np.testing.assert_array_equal(flatpatches.flatten_stepped_floors(lattice, vertex), vertex)
    # each terrace's cells next to a step up, and next to a step down, lie along a line
    split = pure_splits(lattice, 2, True)
    patches, count = flatpatches.ndimage.label(split, flatpatches._IN_PLANE)
    below, above = flatpatches.step_reach(split)
    for cells in (split & below, split & above):
        assert flatpatches.step_roundness(patches, cells, count).max() < tol.floor_roundness


def test_step_roundness_is_zero_on_a_line_and_one_on_a_ring():
    patches = np.zeros((40, 40, 2), dtype=int)
    steps = np.zeros(patches.shape, dtype=bool)
    patches[..., 0], patches[..., 1] = 1, 2
    steps[5:35, 10, 0] = True
    v, u = np.mgrid[:40, :40]
    steps[..., 1] = np.abs(np.hypot(v - 20, u - 20) - 10) < 0.7
    np.testing.assert_allclose(flatpatches.step_roundness(patches, steps, 2), [0, 0, 1],
                               atol=0.02)


def test_remesh_puts_a_layered_caps_floors_nearer_their_true_faces(monkeypatch):
    """The shipped network reads a generated cap's one-layer steps as a gently tilted plane and
    leaves its flat floors off their faces; the stepped floors stage moves them nearer
    (the grid alone, 64³; docs/experiments/layered-parts.md)."""
    import trimesh

    from agndc_core import pipeline
    from agndc_core.voxelize import voxelize
    from conftest import research_script

    vertices, faces = research_script("layered_caps").layered_cap(22)
    voxelised = voxelize(vertices, faces, 64)
    grid = VoxelGrid(voxelised.occupancy, affine=voxelised.affine)  # without the bounds
    on = remesh(grid, method="agndc", threads=1)
    monkeypatch.setattr(pipeline, "STEPPED_FLOORS", False)
    off = remesh(grid, method="agndc", threads=1)
    assert "stepped floors" in on.timings and "stepped floors" not in off.timings
    moved = np.abs(on.vertices - off.vertices).max(axis=1) > 1e-6
    assert moved.sum() > 1000
    truth = trimesh.Trimesh(vertices, faces)
    voxel = np.linalg.norm(voxelised.affine[:3, 0])

    def mean_distance(points):
        return np.abs(trimesh.proximity.signed_distance(truth, points)).mean() / voxel

    before, after = mean_distance(off.vertices[moved]), mean_distance(on.vertices[moved])
    assert after < 0.7 * before
