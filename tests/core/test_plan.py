"""plan.py: grid plans agree with voxelize, limits, estimates, open edges, nearest-face values."""

import math

import numpy as np
import pytest

from agndc_core import plan
from agndc_core import voxelize as voxelize_module
from agndc_core.errors import MeshError
from agndc_core.grid import MAX_VOXELS, pad_to_lattice
from agndc_core.labels import crossed_edges
from agndc_core.study.shapes import cad_part
from agndc_core.voxelize import voxelize


def box(lo, hi):
    """A closed, outward box mesh: (8, 3) vertices, (12, 3) faces."""
    corners = np.array([[(k >> d) & 1 for d in range(3)] for k in range(8)], dtype=np.float64)
    vertices = np.asarray(lo) + corners * (np.asarray(hi) - np.asarray(lo))
    quads = [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)]
    faces = [(a, b, c) for a, b, c, d in quads] + [(a, c, d) for a, b, c, d in quads]
    return vertices, np.array(faces, dtype=np.int64)


@pytest.mark.parametrize("seed", range(6))
def test_plan_matches_voxelize(seed):
    rng = np.random.default_rng(seed)
    vertices, faces = box(rng.normal(size=3), rng.normal(size=3) + rng.uniform(0.2, 3, size=3) + 3)
    resolution = int(rng.integers(plan.RESOLUTION_MIN, 60))
    grid = voxelize(vertices, faces, resolution)
    got = plan.plan_grid(np.ptp(vertices, axis=0), resolution=resolution)
    assert got.shape == grid.shape and got.resolution == resolution
    np.testing.assert_allclose(got.voxel_size, grid.voxel_size[0])
    # the voxel size that plan chose for a wanted size: never larger than asked, and voxelize
    # at the planned resolution makes exactly that grid
    wanted = float(rng.uniform(0.05, 0.5))
    by_size = plan.plan_grid(np.ptp(vertices, axis=0), voxel_size=wanted)
    assert by_size.voxel_size <= wanted * (1 + 1e-12)
    assert by_size.voxel_size > wanted * (by_size.resolution - 3) / (by_size.resolution - 2) - 1e-12
    assert voxelize(vertices, faces, by_size.resolution).shape == by_size.shape


def test_limits_match_voxelize():
    vertices, faces = box((0, 0, 0), (1, 0.01, 0.01))  # thin: 1024 along x stays small
    voxelize(vertices, faces, plan.RESOLUTION_MAX)
    voxelize(vertices, faces, plan.RESOLUTION_MIN)
    for bad in (plan.RESOLUTION_MIN - 1, plan.RESOLUTION_MAX + 1):
        with pytest.raises(MeshError, match="resolution"):
            voxelize(vertices, faces, bad)
        with pytest.raises(MeshError, match=f"got {bad}"):
            plan.plan_grid((1, 0.01, 0.01), resolution=bad)


def test_too_fine_voxel_size_says_what_works():
    with pytest.raises(MeshError, match=r"Cube: a voxel size of 0\.001 gives 2,002 voxels.*at "
                                        r"least 0\.00") as info:
        plan.plan_grid((2, 2, 1), voxel_size=0.001, source="Cube")
    # 0.00196 would do per side (1,022 voxels) but not in total (1022x1022x512): not advised
    advised = float(str(info.value).rsplit(" ", 1)[-1])
    assert advised > 0.00196 and plan.plan_grid((2, 2, 1), voxel_size=advised)
    # a cube at 700 voxels per side is within the resolution limit but over MAX_VOXELS
    with pytest.raises(MeshError, match="more than the 216,000,000") as info:
        plan.plan_grid((1, 1, 1), voxel_size=1 / 700)
    suggested = float(str(info.value).rsplit(" ", 1)[-1])
    assert plan.plan_grid((1, 1, 1), voxel_size=suggested).voxels <= MAX_VOXELS
    with pytest.raises(MeshError, match="positive"):
        plan.plan_grid((1, 1, 1), voxel_size=0.0)
    with pytest.raises(MeshError, match="zero size"):
        plan.plan_grid((0, 0, 0), voxel_size=0.1)


def test_crossings_estimate_counts_crossed_edges():
    vertices, faces = cad_part(7)
    for resolution in (32, 64):
        grid = voxelize(vertices, faces, resolution)
        counted = int(crossed_edges(pad_to_lattice(grid.occupancy)).sum())
        assert plan.grid_crossings(grid.occupancy) == counted
        estimated = plan.mesh_crossings(vertices, faces, float(grid.voxel_size[0]))
        assert abs(estimated / counted - 1) < 0.1


def test_crossings_estimate_in_chunks_checks_between_them(monkeypatch):
    """A run's expected times read every triangle before its first stage: in chunks, with a
    check before each, and the same estimate whatever the chunk size."""
    from agndc_core.errors import CancelledError
    from agndc_core.pipeline import remesh_mesh

    vertices, faces = cad_part(7)
    whole = plan.mesh_crossings(vertices, faces, 0.02)
    monkeypatch.setattr(voxelize_module, "TRIANGLE_CHUNK", 100)  # voxelize.triangle_chunks
    calls = []
    assert plan.mesh_crossings(vertices, faces, 0.02, check=lambda: calls.append(1)) == whole
    assert len(calls) == -(-len(faces) // 100)

    class CancelInside:
        def is_set(self):
            return "mesh_crossings" in {frame.f_code.co_name for frame in _frames()}

    with pytest.raises(CancelledError):
        remesh_mesh(vertices, faces, resolution=24, method="mc", cancel=CancelInside(),
                    progress=lambda fraction, message: None)


def _frames():
    """The calling frames, innermost first."""
    import sys

    frame = sys._getframe(1)
    while frame is not None:
        yield frame
        frame = frame.f_back


def test_estimate_grows_with_the_grid():
    small = plan.estimate_seconds("agndc", (64, 64, 64), 30_000)
    large = plan.estimate_seconds("agndc", (128, 128, 128), 120_000)
    assert 0 < small < large
    assert plan.estimate_seconds("mc", (128, 128, 128), 120_000) < large
    with_distances = plan.estimate_seconds("agndc", (64, 64, 64), 30_000, distances=2)
    assert with_distances > small
    two = plan.estimate_seconds("agndc", (64, 64, 64), 30_000, threads=2)
    many = plan.estimate_seconds("agndc", (64, 64, 64), 30_000, threads=64)
    assert plan.SERIAL_SHARE["agndc"] * small < many < two < small  # more threads help, not fully
    assert plan.estimate_seconds("mc", (64, 64, 64), 30_000, threads=8) == plan.estimate_seconds(
        "mc", (64, 64, 64), 30_000)


def test_open_edge_count():
    vertices, faces = box((0, 0, 0), (1, 1, 1))
    assert plan.open_edge_count(vertices, faces) == 0
    # one side (faces 5 and 11) removed: a square hole
    assert plan.open_edge_count(vertices, np.delete(faces, [5, 11], axis=0)) == 4
    # split into one vertex per face corner (an unwelded STL): still closed
    split = vertices[faces].reshape(-1, 3)
    assert plan.open_edge_count(split, np.arange(len(split)).reshape(-1, 3)) == 0
    assert plan.open_edge_count(vertices[:3], np.array([[0, 1, 2]])) == 3


def test_nearest_face_values_on_a_box():
    """Each side of a box carries its own value; points on (and just off) each side get it."""
    vertices, faces = box((0, 0, 0), (2, 1, 1))
    side = np.arange(12) % 6  # faces k and k + 6 share a side
    rng = np.random.default_rng(0)
    centre, half = np.array([1.0, 0.5, 0.5]), np.array([1.0, 0.5, 0.5])
    normals = np.array([[0, 0, -1], [0, 0, 1], [0, -1, 0], [0, 1, 0], [-1, 0, 0], [1, 0, 0]])
    for k, normal in enumerate(normals):
        # points on side k, away from its edges by 5 % of the box, lifted by a little noise
        uv = rng.uniform(-0.9, 0.9, size=(200, 3)) * (1 - np.abs(normal))
        points = centre + (uv + normal) * half + normal * rng.uniform(-0.01, 0.01, (200, 1))
        got = plan.nearest_face_values(vertices, faces, side, points)
        assert np.all(got == k), k
    same = plan.nearest_face_values(vertices, faces, np.zeros(12, int), centre[None])
    assert same.tolist() == [0]
    assert math.isfinite(float(plan.nearest_face_values(vertices, faces, side, centre[None])[0]))


def test_free_offset_skips_occupied_boxes():
    lo, hi = np.zeros(3), np.array([2.0, 1.0, 1.0])
    x = np.array([1.0, 0.0, 0.0])
    # nothing in the way: one step (width 2 + 25 % gap) to the right
    np.testing.assert_allclose(plan.free_offset(lo, hi, x, lo[None], hi[None]), [2.5, 0, 0])
    # the first slot is taken by another object: the next free one
    blocker_lo, blocker_hi = np.array([[2.6, 0.2, 0.2]]), np.array([[3.0, 0.5, 0.5]])
    got = plan.free_offset(lo, hi, x, np.vstack([lo, blocker_lo]), np.vstack([hi, blocker_hi]))
    np.testing.assert_allclose(got, [5.0, 0, 0])
    # an object beside but not in the way (other y) does not count; start=0 allows in place
    np.testing.assert_allclose(plan.free_offset(lo, hi, x, [[0, 5, 0]], [[1, 6, 1]], start=0), 0)
    # along a rotated direction the step is the box's width along it
    d = np.array([1.0, 1.0, 0.0])
    got = plan.free_offset(lo, hi, d, lo[None], hi[None])
    np.testing.assert_allclose(got, d / np.sqrt(2) * (3 / np.sqrt(2)) * 1.25)


def test_is_planar():
    vertices, faces = box((0, 0, 0), (1, 1, 1))
    assert not plan.is_planar(vertices)
    assert plan.is_planar(np.eye(3))  # one triangle
    rotation = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    square = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float) @ rotation.T
    assert plan.is_planar(square + 5.0)
    assert not plan.is_planar(np.vstack([square, [[0, 0, 1e-3]] @ rotation.T]))


@pytest.mark.parametrize("extent", [(2.0, 2.0, 2.0), (1.0, 0.2, 0.1), (300.0, 120.0, 80.0),
                                    (0.18, 0.1, 0.07)])
def test_the_advised_voxel_size_works_in_one_step(extent):
    """Too fine a voxel size names a size that satisfies both limits (voxels per side and in
    total): using it plans a grid at once."""
    import re

    for voxel_size in (min(extent) * 1e-4, max(extent) / 2000):
        with pytest.raises(MeshError) as caught:
            plan.plan_grid(extent, voxel_size=voxel_size)
        advised = float(re.search(r"at least ([0-9.e-]+)", str(caught.value)).group(1))
        grid = plan.plan_grid(extent, voxel_size=advised)
        assert grid.voxels <= plan.MAX_VOXELS and grid.resolution <= plan.RESOLUTION_MAX
